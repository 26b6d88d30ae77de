#!/usr/bin/python3
"""Makes the small GeoTIFF and ASCII-grid fixtures of tests/suite/gdal_written.rs with GDAL itself
(run with /usr/bin/python3, which has osgeo; GDAL 3.6 made the committed files). Each is a
layout GDAL writes that vtz once read or wrote wrong (issue 35, items 3, 4 and 16)."""
import numpy as np
from osgeo import gdal, osr

gdal.UseExceptions()
gdal.SetConfigOption("GDAL_TIFF_INTERNAL_MASK", "YES")
wgs84 = osr.SpatialReference()
wgs84.ImportFromEPSG(4326)


def values(w, h):
    y, x = np.mgrid[0:h, 0:w]
    return (100.0 + 3.0 * x + 0.5 * y * y + 0.25 * x * y).astype(np.float32)


def masked(w, h):
    """Valid where True: a disc cut out, and the first column."""
    y, x = np.mgrid[0:h, 0:w]
    m = (x - w * 0.6) ** 2 + (y - h * 0.4) ** 2 > (min(w, h) * 0.3) ** 2
    m[:, 0] = False
    return m


def with_mask(name, w, h, options, driver="GTiff"):
    v = values(w, h)
    m = masked(w, h)
    v[~m] = 0.0  # what GDAL leaves under a mask
    mem = gdal.GetDriverByName("MEM").Create("", w, h, 1, gdal.GDT_Float32)
    mem.SetGeoTransform([500000.0, 30.0, 0.0, 4100000.0, 0.0, -30.0])
    srs = osr.SpatialReference()
    srs.ImportFromEPSG(32611)
    mem.SetProjection(srs.ExportToWkt())
    mem.GetRasterBand(1).WriteArray(v)
    mem.CreateMaskBand(gdal.GMF_PER_DATASET)
    mem.GetRasterBand(1).GetMaskBand().WriteArray(m.astype(np.uint8) * 255)
    if driver == "COG":
        mem.BuildOverviews("NEAREST", [2])
    gdal.GetDriverByName(driver).CreateCopy(name, mem, options=options)


# Item 3: south-up (row 0 at the south), as NetCDF/GRIB conversions write it.
w, h = 7, 5
ds = gdal.GetDriverByName("GTiff").Create("south_up.tif", w, h, 1, gdal.GDT_Float32)
ds.SetGeoTransform([10.0, 0.5, 0.0, 40.0, 0.0, 0.25])
ds.SetProjection(wgs84.ExportToWkt())
ds.GetRasterBand(1).WriteArray(values(w, h))
ds = None

# Item 16: an internal mask, no nodata; strips, tiles, and a COG with an overview.
with_mask("mask_strips.tif", 37, 23, ["COMPRESS=DEFLATE", "BLOCKYSIZE=5"])
with_mask("mask_tiles_lzw.tif", 37, 23, ["COMPRESS=LZW", "TILED=YES", "BLOCKXSIZE=16", "BLOCKYSIZE=16"])
with_mask("mask_packbits.tif", 37, 23, ["COMPRESS=PACKBITS"])
with_mask("mask_none.tif", 37, 23, [])
with_mask("mask_cog.tif", 200, 150, ["COMPRESS=DEFLATE", "PREDICTOR=YES", "BLOCKSIZE=128"], driver="COG")

# Item 4: GDAL's ASCII grid of a float raster whose nodata is NaN.
v = values(4, 3)
v[1, 1] = np.nan
mem = gdal.GetDriverByName("MEM").Create("", 4, 3, 1, gdal.GDT_Float32)
mem.SetGeoTransform([10.0, 1.0, 0.0, 20.0, 0.0, -1.0])
mem.GetRasterBand(1).WriteArray(v)
mem.GetRasterBand(1).SetNoDataValue(float("nan"))
gdal.GetDriverByName("AAIGrid").CreateCopy("nan_nodata.asc", mem)
