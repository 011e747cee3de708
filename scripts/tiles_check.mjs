// Checks a tileset written by `insgen export-tiles` with CesiumJS's own math and 3d-tiles-tools.
//
//   node scripts/tiles_check.mjs TILESET_DIR SCENE_DIR
//
// - 3d-tiles-tools (CesiumGS) reads tileset.json and traverses it, resolving each tile's transform and
//   content; its content-type registry must see the content as glTF binary.
// - gltf-transform (through 3d-tiles-tools' IO, Draco and meshopt registered) reads the GLB: positions and
//   the `_FEATURE_ID_0` attribute; the GLB JSON must declare EXT_mesh_features and
//   EXT_structural_metadata with a `source_id` property table.
// - @cesium/engine (CesiumJS's engine, as a viewer computes it) places every vertex: ECEF = tile
//   transform · Axis.Y_UP_TO_Z_UP · p. The reference is CesiumJS's own ENU frame at the manifest's
//   origin (Transforms.eastNorthUpToFixedFrame of Cartesian3.fromDegrees), applied to the vertex's ENU
//   position (x, −z, y) — insgen's ENU→ECEF code is not used for the reference.
//
// Prints one JSON object: max vertex distance (m), vertices checked, feature ids found, ids whose
// vertices fall outside their building's ENU box (buildings.json, 1 cm tolerance), and the content type.
import fs from "node:fs";
import path from "node:path";
import tools from "3d-tiles-tools";
import { Axis, Cartesian3, Matrix4, Transforms } from "@cesium/engine";

const [tilesetDir, sceneDir] = process.argv.slice(2);
const manifest = JSON.parse(fs.readFileSync(path.join(sceneDir, "manifest.json"), "utf8"));
const buildings = JSON.parse(fs.readFileSync(path.join(sceneDir, "buildings.json"), "utf8"));
const tilesetJson = JSON.parse(fs.readFileSync(path.join(tilesetDir, "tileset.json"), "utf8"));

const resolver = tools.ResourceResolvers.createFileResourceResolver(tilesetDir);
const traverser = new tools.TilesetTraverser(tilesetDir, resolver, { depthFirst: true });
const tiles = [];
await traverser.traverse(tilesetJson, async (t) => {
  // The transform of the tile in ECEF: the product of the transforms from the root down.
  const finalTile = t.asFinalTile();
  const contents = t.getFinalContents().map((c) => c.uri);
  tiles.push({ transform: finalTile.transform, contents, level: t.level });
  return true;
});

const out = { tiles: tiles.length, contents: [], content_types: [], max_vertex_error_m: 0, vertices: 0 };
const origin = Cartesian3.fromDegrees(manifest.origin.lon_deg, manifest.origin.lat_deg, manifest.origin.h_m);
const enuToEcef = Transforms.eastNorthUpToFixedFrame(origin);
const byId = new Map(buildings.map((b) => [b.id, b]));
const io = await tools.GltfTransform.getIO();
const featureIds = new Set();
const outside = new Set();
for (const tile of tiles) {
  const transform = tile.transform ? Matrix4.fromColumnMajorArray(tile.transform) : Matrix4.IDENTITY;
  for (const uri of tile.contents) {
    out.contents.push(uri);
    const bytes = fs.readFileSync(path.join(tilesetDir, uri));
    const type = await tools.ContentDataTypeRegistry.findContentDataType(
      new tools.BufferedContentData(uri, bytes),
    );
    out.content_types.push(type);
    // The GLB JSON chunk: the extensions a viewer needs for picking.
    const jsonLen = bytes.readUInt32LE(12);
    const gltf = JSON.parse(bytes.subarray(20, 20 + jsonLen).toString("utf8"));
    out.extensions_used = gltf.extensionsUsed ?? [];
    const props = gltf.extensions?.EXT_structural_metadata?.schema?.classes?.building?.properties ?? {};
    out.property_names = Object.keys(props);
    out.feature_id_sets = gltf.meshes.flatMap((m) =>
      m.primitives.map((p) => p.extensions?.EXT_mesh_features?.featureIds ?? []),
    );
    const doc = await io.readBinary(new Uint8Array(bytes));
    const model = Matrix4.multiply(transform, Axis.Y_UP_TO_Z_UP, new Matrix4());
    for (const mesh of doc.getRoot().listMeshes()) {
      for (const prim of mesh.listPrimitives()) {
        const pos = prim.getAttribute("POSITION");
        const fid = prim.getAttribute("_FEATURE_ID_0");
        const n = pos.getCount();
        const step = Math.max(1, Math.floor(n / 5000));
        const p = [0, 0, 0];
        const f = [0];
        for (let i = 0; i < n; i += step) {
          pos.getElement(i, p);
          const local = new Cartesian3(p[0], p[1], p[2]);
          const viaTileset = Matrix4.multiplyByPoint(model, local, new Cartesian3());
          const enu = new Cartesian3(p[0], -p[2], p[1]);
          const reference = Matrix4.multiplyByPoint(enuToEcef, enu, new Cartesian3());
          const d = Cartesian3.distance(viaTileset, reference);
          out.max_vertex_error_m = Math.max(out.max_vertex_error_m, d);
          out.vertices += 1;
          if (fid) {
            fid.getElement(i, f);
            const id = Math.round(f[0]);
            featureIds.add(id);
            const b = byId.get(id);
            const e = [enu.x, enu.y, enu.z];
            if (!b || e.some((v, k) => v < b.bbox_min_enu_m[k] - 0.01 || v > b.bbox_max_enu_m[k] + 0.01)) {
              outside.add(id);
            }
          }
        }
      }
    }
  }
}
out.feature_ids = featureIds.size;
out.outside_their_building = [...outside];
out.root_transform_matches_manifest = tiles[0].transform.every(
  (v, i) => v === manifest.ecef_from_enu[i % 4][Math.floor(i / 4)],
);
console.log(JSON.stringify(out));
