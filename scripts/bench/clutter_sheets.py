"""Contact sheets for bench/clutter.md: demo frames without | with clutter, and the side-by-side picture.

Usage: python scripts/bench/clutter_sheets.py OFF_WORKDIR ON_WORKDIR OUT_DIR
Reads the demo's cam2 RGB frames of two work directories prepared without and with clutter (same seed
and poses; see bench/clutter.md for the commands) and ON_WORKDIR/demo/cam2/rgb/side_by_side.png. Writes
OUT_DIR/clutter_demo_off_on.png and OUT_DIR/clutter_side_by_side.png (palette PNGs, a few hundred KB).
"""
import glob, os, sys
from PIL import Image
if len(sys.argv) != 4:
    sys.exit(__doc__)
off_dir, on_dir, out_dir = sys.argv[1:4]
rgb = lambda w: os.path.join(w, 'demo', 'cam2', 'rgb')
off = sorted(glob.glob(os.path.join(rgb(off_dir), 'demo_cam2_*.png')))
on = sorted(glob.glob(os.path.join(rgb(on_dir), 'demo_cam2_*.png')))
assert off, f"no demo cam2 RGB frames under {rgb(off_dir)}"
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
sheet.quantize(colors=160, method=Image.MEDIANCUT, dither=Image.FLOYDSTEINBERG).save(os.path.join(out_dir, "clutter_demo_off_on.png"), optimize=True)
sb = Image.open(os.path.join(rgb(on_dir), 'side_by_side.png')).convert('RGB')
sb.quantize(colors=256, method=Image.MEDIANCUT, dither=Image.FLOYDSTEINBERG).save(os.path.join(out_dir, 'clutter_side_by_side.png'), optimize=True)
