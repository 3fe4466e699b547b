"""bathy: the open survey pipeline for airborne bathymetric lidar.

Importing the package points numba's cache of compiled kernels at a folder of the kernels'
own version (:func:`pipeline.kernel_cache.use_kernel_cache`), before any kernel is defined.
"""

from pipeline.kernel_cache import use_kernel_cache

use_kernel_cache()
