"""QGIS draws a .vtz through the GDAL plugin: a hillshade of the whole raster, timed.

    GDAL_DRIVER_PATH=target/gdal-plugin QT_QPA_PLATFORM=offscreen \\
        python3 capi/gdal/qgis_render.py FILE.vtz OUT.png [SIZE] [REPEATS]

Uses Debian's QGIS Python bindings (python3-qgis) headless: opens FILE with the "gdal"
provider (so through the VTZ driver), renders the full extent at SIZE x SIZE pixels with
QgsMapRendererParallelJob (QGIS's own parallel renderer, as its map canvas) and saves the
picture. Prints the provider's driver, the layer's size and CRS, and the wall time of each
render: the first in a freshly opened layer, then REPEATS more in new layers (each opens
the file again, so the GDAL block cache of the previous layer does not help).
"""

import os
import sys
import time

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from qgis.core import (  # noqa: E402
    QgsApplication,
    QgsHillshadeRenderer,
    QgsMapRendererParallelJob,
    QgsMapSettings,
    QgsRasterLayer,
)
from qgis.PyQt.QtCore import QSize  # noqa: E402
from qgis.PyQt.QtGui import QColor  # noqa: E402


def render(path, size, out=None):
    layer = QgsRasterLayer(path, "dem", "gdal")
    if not layer.isValid():
        raise SystemExit(f"QGIS could not open {path}: {layer.error().summary()}")
    shade = QgsHillshadeRenderer(layer.dataProvider(), 1, 315.0, 45.0)
    if layer.crs().isGeographic():
        # Heights in metres over degrees: about 111 km to a degree.
        shade.setZFactor(1.0 / 111320.0)
    layer.setRenderer(shade)
    settings = QgsMapSettings()
    settings.setLayers([layer])
    settings.setDestinationCrs(layer.crs())
    settings.setExtent(layer.extent())
    settings.setOutputSize(QSize(size, size))
    settings.setBackgroundColor(QColor(255, 255, 255))
    job = QgsMapRendererParallelJob(settings)
    t0 = time.perf_counter()
    job.start()
    job.waitForFinished()
    dt = time.perf_counter() - t0
    if out:
        job.renderedImage().save(out)
    ds = layer.dataProvider()
    about = (
        f"{layer.width()} x {layer.height()}, CRS {layer.crs().authid() or '(none)'},"
        f" overviews {ds.hasPyramids()}"
    )
    # QGIS objects go before exitQgis (else the interpreter's teardown crashes).
    del job, settings, layer
    return about, dt


def main():
    path, out = sys.argv[1], sys.argv[2]
    size = int(sys.argv[3]) if len(sys.argv) > 3 else 1024
    repeats = int(sys.argv[4]) if len(sys.argv) > 4 else 2
    app = QgsApplication([], False)
    app.initQgis()
    from osgeo import gdal

    drv = gdal.OpenEx(path).GetDriver().ShortName
    about, first = render(path, size, out)
    print(f"{path}: GDAL driver {drv}, {about}")
    times = [first] + [render(path, size)[1] for _ in range(repeats)]
    print("render s: " + ", ".join(f"{t:.3f}" for t in times))
    print(f"picture: {out} ({size} x {size})")
    app.exitQgis()


if __name__ == "__main__":
    main()
