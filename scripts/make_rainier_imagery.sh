#!/usr/bin/env bash
# Derives data/terrain/mt_rainier_imagery.tif, the colour image the demo drapes over the shipped
# SRTM tile. It is not photography: it is the tile's own heights coloured by a land-cover-like
# elevation ramp (conifer forest, subalpine meadow, rock, snow and glaciers above 2,000 m), its
# voids first filled by GDAL's inverse-distance fill (gdal_fillnodata), reprojected into UTM zone
# 10N (EPSG:32610) at 40 m pixels and stored as a JPEG-compressed GeoTIFF with a validity mask. Being in another reference system and
# at another resolution than the DEM, it exercises what real imagery needs: reprojection and an
# independent resolution (the build stores it at 2 samples per DEM interval).
# Needs GDAL's command-line tools and Python scripts (Debian gdal-bin, python3-gdal).
set -euo pipefail
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cat > "$tmp/ramp.txt" <<'RAMP'
nv 0 0 0 0
0 52 78 48
700 44 74 42
1300 58 86 48
1650 112 118 74
1850 150 140 112
2000 226 230 236
4500 250 251 255
RAMP
/usr/bin/python3 /usr/bin/gdal_fillnodata.py -q -md 200 data/terrain/mt_rainier_90m.tif "$tmp/filled.tif"
gdaldem color-relief -q -alpha "$tmp/filled.tif" "$tmp/ramp.txt" "$tmp/relief.tif"
# The UTM rectangle inside the tile's footprint (so the image has no empty corners).
gdalwarp -q -overwrite -t_srs EPSG:32610 -te 578000 5096000 652000 5205600 -tr 40 40 -r bilinear \
  -srcalpha -dstalpha "$tmp/relief.tif" "$tmp/utm.tif"
gdal_translate -q -b 1 -b 2 -b 3 -mask 4 --config GDAL_TIFF_INTERNAL_MASK YES -co COMPRESS=JPEG \
  -co PHOTOMETRIC=YCBCR -co JPEG_QUALITY=88 -co TILED=YES "$tmp/utm.tif" data/terrain/mt_rainier_imagery.tif
echo "wrote data/terrain/mt_rainier_imagery.tif"
