# Builds tests/data/gdaldem_k3.npz: a 12 x 12 random float32 DEM and gdaldem's TRI (Wilson), TRI (Riley), TPI
# and roughness of it. Run with the system python that has python3-gdal (Debian GDAL 3.6.2).
import subprocess, sys
import numpy as np
from osgeo import gdal

rng = np.random.default_rng(20261121)
dem = rng.random((12, 12), dtype=np.float64).astype(np.float32)
drv = gdal.GetDriverByName("GTiff")
ds = drv.Create("dem.tif", 12, 12, 1, gdal.GDT_Float32)
ds.SetGeoTransform((0.0, 1.0, 0.0, 12.0, 0.0, -1.0))
ds.GetRasterBand(1).WriteArray(dem)
ds = None
cmds = {
    "tri_wilson": ["gdaldem", "TRI", "dem.tif", "tri_wilson.tif", "-alg", "Wilson", "-q"],
    "tri_riley": ["gdaldem", "TRI", "dem.tif", "tri_riley.tif", "-alg", "Riley", "-q"],
    "tpi": ["gdaldem", "TPI", "dem.tif", "tpi.tif", "-q"],
    "roughness": ["gdaldem", "roughness", "dem.tif", "roughness.tif", "-q"],
}
out = {"dem": dem}
for name, cmd in cmds.items():
    subprocess.run(cmd, check=True)
    ods = gdal.Open(f"{name}.tif")  # keep the dataset alive while its band is read
    b = ods.GetRasterBand(1)
    out[name] = b.ReadAsArray().astype(np.float32)
    out[name + "_nodata"] = np.float32(b.GetNoDataValue())
    print(name, " ".join(cmd), out[name].dtype, out[name][0, :3], out[name][1, 1:4])
ids = gdal.Open("dem.tif")
back = ids.GetRasterBand(1).ReadAsArray()
assert np.array_equal(back, dem)
out["gdal_version"] = np.array(gdal.__version__)
out["commands"] = np.array(["  ".join(c) for c in cmds.values()])
np.savez(sys.argv[1], **out)
