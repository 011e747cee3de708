"""Contact sheets for bench/clutter.md: demo frames without | with clutter, and the side-by-side picture.

Usage: python scripts/bench/clutter_sheets.py OUT_DIR
Reads the RGB frames of two work directories prepared without and with clutter (same seed and poses):
/tmp/bench_clutter_off and /tmp/bench_clutter_on (see bench/clutter.md for the commands), and
/tmp/bench_clutter_on/demo/cam2/rgb/side_by_side.png. Writes OUT_DIR/clutter_demo_off_on.png and
OUT_DIR/clutter_side_by_side.png (palette PNGs, a few hundred KB).
"""
import glob, os, sys
from PIL import Image
off = sorted(glob.glob('/tmp/bench_clutter_off/demo/cam2/rgb/demo_cam2_*.png'))
on = sorted(glob.glob('/tmp/bench_clutter_on/demo/cam2/rgb/demo_cam2_*.png'))
assert [os.path.basename(p) for p in off] == [os.path.basename(p) for p in on], (off, on)
W, GAP = 400, 4
tiles = []
for a, b in zip(off, on):
    ia, ib = Image.open(a).convert('RGB'), Image.open(b).convert('RGB')
    h = round(ia.height * W / ia.width)
    tiles.append((ia.resize((W, h), Image.LANCZOS), ib.resize((W, h), Image.LANCZOS)))
h = tiles[0][0].height
sheet = Image.new('RGB', (GAP + 2 * (W + GAP), GAP + len(tiles) * (h + GAP)), (25, 25, 25))
for r, (a, b) in enumerate(tiles):
    sheet.paste(a, (GAP, GAP + r * (h + GAP)))
    sheet.paste(b, (2 * GAP + W, GAP + r * (h + GAP)))
sheet.quantize(colors=160, method=Image.MEDIANCUT, dither=Image.FLOYDSTEINBERG).save(sys.argv[1] + "/clutter_demo_off_on.png", optimize=True)
sb = Image.open('/tmp/bench_clutter_on/demo/cam2/rgb/side_by_side.png').convert('RGB')
sb.quantize(colors=256, method=Image.MEDIANCUT, dither=Image.FLOYDSTEINBERG).save(sys.argv[1] + '/clutter_side_by_side.png', optimize=True)
