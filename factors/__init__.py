"""graphloc.factors (source folder factors/): measurements -> GTSAM factors."""
