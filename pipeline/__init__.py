"""bathy: the open survey pipeline for airborne bathymetric lidar."""
