// Opens a tileset written by `insgen export-tiles` in CesiumJS, in headless Chromium, and reports where
// CesiumJS put it: the root tile's computed transform, and what a click at points of the screen picks
// (the building feature with its `source_id`, and the picked position in ECEF).
//
//   node scripts/cesium_check.mjs TILESET_DIR [CHROMIUM]
//
// A local HTTP server on 127.0.0.1 (an ephemeral port) serves CesiumJS (node_modules/cesium/Build/Cesium),
// the tileset and a page; Chromium renders with SwiftShader (software WebGL), no network, no imagery, no
// terrain (the WGS84 ellipsoid). The page posts its findings back to the server; this script prints them
// as one JSON object and exits. It gives up after 400 s (exit 2): a watchdog, not a speed bound
// (SwiftShader on a loaded 2-core machine took longer than 150 s once).
import { spawn } from "node:child_process";
import fs from "node:fs";
import http from "node:http";
import os from "node:os";
import path from "node:path";
import { fileURLToPath } from "node:url";

const [tilesetDir, chromium = "chromium"] = process.argv.slice(2);
const repo = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "..");
const cesiumDir = path.join(repo, "node_modules/cesium/Build/Cesium");

const page = `<!doctype html><html><head><meta charset="utf-8">
<script>window.CESIUM_BASE_URL = "/cesium/";</script>
<script src="/cesium/Cesium.js"></script>
<link rel="stylesheet" href="/cesium/Widgets/widgets.css">
<style>html,body,#c{margin:0;width:640px;height:480px;overflow:hidden}</style></head>
<body><div id="c"></div><script>
const report = (r) => fetch("/result", {method: "POST", body: JSON.stringify(r)});
const frames = (n) => new Promise((res) => { const f = () => (n-- <= 0 ? res() : requestAnimationFrame(f)); f(); });
(async () => {
  try {
    const widget = new Cesium.CesiumWidget("c", {
      baseLayer: false, terrainProvider: new Cesium.EllipsoidTerrainProvider(), skyBox: false,
      skyAtmosphere: false, shadows: false, requestRenderMode: false,
      contextOptions: {webgl: {preserveDrawingBuffer: true}},
    });
    const scene = widget.scene;
    scene.globe.show = false;
    const tileset = await Cesium.Cesium3DTileset.fromUrl("/tileset/tileset.json");
    scene.primitives.add(tileset);
    const sphere = tileset.boundingSphere;
    scene.camera.viewBoundingSphere(sphere, new Cesium.HeadingPitchRange(0, -Cesium.Math.PI_OVER_TWO, sphere.radius * 1.6));
    scene.camera.lookAtTransform(Cesium.Matrix4.IDENTITY);
    const loaded = new Promise((res) => tileset.allTilesLoaded.addEventListener(res));
    await Promise.race([loaded, new Promise((res) => setTimeout(res, 60000))]);
    await frames(10);
    const picks = [];
    const canvas = scene.canvas;
    for (let j = 1; j < 12; j++) {
      for (let i = 1; i < 12; i++) {
        const xy = new Cesium.Cartesian2(Math.floor(canvas.clientWidth * i / 12) + 0.5, Math.floor(canvas.clientHeight * j / 12) + 0.5);
        // A 1×1 pick rectangle: the feature under exactly the pixel whose depth pickPosition reads.
        const f = scene.pick(xy, 1, 1);
        if (!(f instanceof Cesium.Cesium3DTileFeature)) continue;
        const p = scene.pickPosition(xy);
        if (!Cesium.defined(p)) continue;
        picks.push({x: xy.x, y: xy.y, feature_id: f.featureId, source_id: f.getProperty("source_id"),
                    ecef_m: [p.x, p.y, p.z]});
      }
    }
    report({
      cesium: Cesium.VERSION,
      tiles_loaded: tileset.tilesLoaded,
      root_computed_transform: Cesium.Matrix4.toArray(tileset.root.computedTransform),
      bounding_sphere_centre_ecef_m: [sphere.center.x, sphere.center.y, sphere.center.z],
      bounding_sphere_radius_m: sphere.radius,
      features_in_root_content: tileset.root.content.featuresLength,
      canvas: [canvas.clientWidth, canvas.clientHeight, canvas.width, canvas.height, window.devicePixelRatio, scene.pickPositionSupported],
      picks,
    });
  } catch (e) {
    report({error: String(e && e.stack || e)});
  }
})();
</script></body></html>`;

const types = { ".js": "text/javascript", ".json": "application/json", ".glb": "model/gltf-binary",
  ".wasm": "application/wasm", ".css": "text/css", ".png": "image/png", ".jpg": "image/jpeg" };
let chrome;
const server = http.createServer((req, res) => {
  const url = decodeURIComponent(req.url.split("?")[0]);
  if (req.method === "POST" && url === "/result") {
    let body = "";
    req.on("data", (d) => (body += d));
    req.on("end", () => {
      res.end("ok");
      console.log(body);
      finish(JSON.parse(body).error ? 1 : 0);
    });
    return;
  }
  let file;
  if (url === "/") file = null;
  else if (url.startsWith("/cesium/")) file = path.join(cesiumDir, url.slice(8));
  else if (url.startsWith("/tileset/")) file = path.join(tilesetDir, url.slice(9));
  if (url === "/") {
    res.setHeader("content-type", "text/html");
    res.end(page);
  } else if (file && fs.existsSync(file) && fs.statSync(file).isFile()) {
    res.setHeader("content-type", types[path.extname(file)] ?? "application/octet-stream");
    fs.createReadStream(file).pipe(res);
  } else {
    res.statusCode = 404;
    res.end();
  }
});

function finish(code) {
  if (chrome) chrome.kill("SIGKILL");
  server.close();
  process.exit(code);
}

server.listen(0, "127.0.0.1", () => {
  const { port } = server.address();
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), "insgen-chromium-"));
  chrome = spawn(chromium, [
    "--headless=new", "--no-sandbox", "--disable-gpu-sandbox", "--no-first-run", "--disable-extensions",
    "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist",
    `--user-data-dir=${profile}`, "--window-size=640,480", `http://127.0.0.1:${port}/`,
  ], { stdio: ["ignore", "ignore", "pipe"] });
  let stderr = "";
  chrome.stderr.on("data", (d) => (stderr = (stderr + d).slice(-4000)));
  chrome.on("exit", (code) => {
    console.log(JSON.stringify({ error: `chromium exited with ${code} before reporting`, stderr }));
    finish(2);
  });
  setTimeout(() => {
    console.log(JSON.stringify({ error: "no report from the page within 400 s", stderr }));
    finish(2);
  }, 400000);
});
