#!/usr/bin/env bash
# GeoTIFF DEMs written by an outside tool (issue #32): GDAL from Debian's packages makes
# DEMs of a known analytic surface about the Chandrayaan-3 site, on a south polar
# stereographic and an equirectangular map of the 1 737 400 m sphere (float32 deflate;
# int16 LZW with a scale, an offset and no-data), plus files the reader must refuse
# (ZSTD compression, no georeference). PROJ (gdaltransform) gives the site's map
# coordinates; the ignored test `terrain_geotiff` checks heights, georeference and the
# site mapping against the analytic values.
#   tools/terrain-e2e.sh      (files in target/terrain-e2e)
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v gdal_translate >/dev/null || ! command -v gdaltransform >/dev/null; then
  apt-get update
  DEBIAN_FRONTEND=noninteractive apt-get install -y gdal-bin
fi
target=${CARGO_TARGET_DIR:-$PWD/target}
out=$target/terrain-e2e
rm -rf "$out"
mkdir -p "$out"

lat=-69.373
lon=32.319
R=1737400
geo="+proj=longlat +R=$R +no_defs"
stere="+proj=stere +lat_0=-90 +lon_0=0 +k=1 +x_0=0 +y_0=0 +R=$R +units=m +no_defs"
eqc="+proj=eqc +lat_ts=0 +lat_0=0 +lon_0=0 +x_0=0 +y_0=0 +R=$R +units=m +no_defs"

# The site's map coordinates by PROJ, rounded to a pixel corner for the raster's centre.
site_xy() { echo "$lon $lat" | gdaltransform -s_srs "$geo" -t_srs "$1" | awk '{printf "%.6f %.6f", $1, $2}'; }
read -r sx sy <<<"$(site_xy "$stere")"
read -r ex ey <<<"$(site_xy "$eqc")"

# An ESRI ASCII grid of h = 100 + 0.01 dx - 0.02 dy + 1e-5 dx dy (dx, dy from the grid's
# centre, m): bilinear in map coordinates, so interpolation reproduces it exactly and a
# flipped axis or half-pixel shift shows. $1 file, $2 centre x, $3 centre y, $4 cell,
# $5 cells per side, $6 value scale (stored = h / scale), $7 offset, $8 "nodata" to put
# -32768 in the first row's first 5 cells. The centre goes to $1.centre.
write_asc() {
  awk -v cx="$2" -v cy="$3" -v c="$4" -v n="$5" -v sc="$6" -v off="$7" -v nd="$8" -v cf="$1.centre" 'BEGIN {
    x0 = sprintf("%.0f", cx / c) * c - n / 2 * c; y0 = sprintf("%.0f", cy / c) * c - n / 2 * c;
    printf "ncols %d\nnrows %d\nxllcorner %.6f\nyllcorner %.6f\ncellsize %.6f\nNODATA_value -32768\n", n, n, x0, y0, c;
    xc = x0 + n / 2 * c; yc = y0 + n / 2 * c;
    for (r = 0; r < n; r++) {
      line = "";
      for (k = 0; k < n; k++) {
        x = x0 + (k + 0.5) * c; y = y0 + (n - r - 0.5) * c;
        dx = x - xc; dy = y - yc;
        h = 100 + 0.01 * dx - 0.02 * dy + 1e-5 * dx * dy;
        v = (h - off) / sc;
        if (sc != 1) v = sprintf("%.0f", v);
        if (nd == "nodata" && r == 0 && k < 5) v = -32768;
        line = line (k ? " " : "") v;
      }
      print line;
    }
    printf "%.6f %.6f\n", xc, yc > cf;
  }' > "$1"
}

write_asc "$out/stere.asc" "$sx" "$sy" 20 200 1 0 none
gdal_translate -q -of GTiff -ot Float32 -co COMPRESS=DEFLATE -a_srs "$stere" \
  "$out/stere.asc" "$out/stere.tif"
# Int16 counts of 0.05 m about a 90 m offset: h = 90 + 0.05 * count.
write_asc "$out/eqc.asc" "$ex" "$ey" 25 160 0.05 90 nodata
gdal_translate -q -of GTiff -ot Int16 -co COMPRESS=LZW -a_srs "$eqc" -a_nodata -32768 \
  -a_scale 0.05 -a_offset 90 "$out/eqc.asc" "$out/eqc.tif"
# Files the reader must refuse with typed errors.
gdal_translate -q -of GTiff -ot Float32 -co COMPRESS=ZSTD -a_srs "$stere" \
  "$out/stere.asc" "$out/stere-zstd.tif"
gdal_translate -q -of GTiff -ot Float32 -co PROFILE=BASELINE \
  "$out/stere.asc" "$out/no-georef.tif"
gdalinfo "$out/stere.tif" > "$out/stere.gdalinfo"
gdalinfo "$out/eqc.tif" > "$out/eqc.gdalinfo"

read -r scx scy < "$out/stere.asc.centre"
read -r ecx ecy < "$out/eqc.asc.centre"
export OILS_TERRAIN_E2E_DIR=$out
export OILS_TERRAIN_E2E_SITE="$lat $lon"
export OILS_TERRAIN_E2E_STERE="$sx $sy $scx $scy"
export OILS_TERRAIN_E2E_EQC="$ex $ey $ecx $ecy"
[ "${OILS_TERRAIN_E2E_NO_TEST:-}" = 1 ] && exit 0
cargo test --release -p oils-emulator --test terrain_geotiff -- --ignored --nocapture
