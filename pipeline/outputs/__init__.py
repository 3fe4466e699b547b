"""Writers of the files people use: figures, JSON budgets, point clouds, grids."""
