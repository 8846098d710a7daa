"""Terrain: a GeoTIFF DEM as WGS84 heights, rays cast onto it, and the `dem` method (docs/terrain.md).

    from pipeline.terrain import Dem, locate_dem
    dem = Dem.open("dem.tif")                       # InputError naming the file if unusable
    lat, lon, h = dem.intersect(origin_lla, direction_enu, label="IMG_0001.JPG pixel (2000, 1500)")
    est = locate_dem(obs, dem, origin_lla, labels=photo_names)   # Estimate(method="dem")
"""

from pipeline.terrain.dem import Dem, VerticalDatum
from pipeline.terrain.flat import FlatGround, ground_covariance_m2
from pipeline.terrain.locate import dem_points, locate_dem

__all__ = ["Dem", "FlatGround", "VerticalDatum", "dem_points", "ground_covariance_m2", "locate_dem"]
