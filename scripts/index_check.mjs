// Opens an export's index.html (written by `insgen export-coco`) from file:// in headless Chromium and
// reports what a person would see: whether every <img> loaded (naturalWidth > 0), whether every link
// and image names a relative path that exists inside the export folder, whether the page asked for any
// resource that is not a local file, and a full-page screenshot.
//
//   node scripts/index_check.mjs INDEX_HTML SCREENSHOT_PNG [CHROMIUM]
//
// Chromium is driven over the DevTools protocol on a pipe (--remote-debugging-pipe: fd 3 in, fd 4
// out; no port, no network), with a fresh profile and the flags of a machine without network. The
// findings are printed as one JSON object; the exit status is 0 when the page is whole, 1 when
// something is missing, 2 when Chromium could not be driven. A watchdog gives up after 120 s.
import { spawn } from "node:child_process";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";
import { pathToFileURL } from "node:url";

const [indexArg, shotArg, chromium = "chromium"] = process.argv.slice(2);
if (!indexArg || !shotArg) {
  console.error("usage: node scripts/index_check.mjs INDEX_HTML SCREENSHOT_PNG [CHROMIUM]");
  process.exit(2);
}
const index = path.resolve(indexArg);
const root = path.dirname(index);
const profile = fs.mkdtempSync(path.join(os.tmpdir(), "insgen-index-chromium-"));
const chrome = spawn(chromium, [
  "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
  "--disable-background-networking", "--disable-component-update", "--disable-sync",
  "--disable-extensions", "--hide-scrollbars", "--remote-debugging-pipe",
  `--user-data-dir=${profile}`, "--window-size=1280,900", "about:blank",
], { stdio: ["ignore", "ignore", "pipe", "pipe", "pipe"] });
let stderr = "";
chrome.stderr.on("data", (d) => (stderr = (stderr + d).slice(-4000)));

let finished = false;
let exited = false;
function finish(code, report) {
  if (finished) return;
  finished = true;
  console.log(JSON.stringify(report));
  // The profile goes once Chromium is gone (it writes into it until then). Its helper processes can
  // outlive it by a moment on a loaded machine and still write there (ENOTEMPTY): retry, and never let
  // the clean-up of a temporary folder change the verdict already printed.
  const done = () => {
    try {
      fs.rmSync(profile, { recursive: true, force: true, maxRetries: 10, retryDelay: 100 });
    } catch (e) {
      process.stderr.write(`index_check: could not remove ${profile}: ${e}\n`);
    }
    process.exit(code);
  };
  if (exited) return done();
  chrome.once("exit", done);
  chrome.kill("SIGKILL");
}
chrome.on("exit", (code) => {
  exited = true;
  finish(2, { error: `chromium exited with ${code}`, stderr });
});
setTimeout(() => finish(2, { error: "no answer from Chromium within 120 s", stderr }), 120000);

// The DevTools protocol: JSON messages separated by NUL bytes.
const toChrome = chrome.stdio[3];
const fromChrome = chrome.stdio[4];
let nextId = 1;
const pending = new Map();
const waiters = [];
let buffer = Buffer.alloc(0);
fromChrome.on("data", (chunk) => {
  buffer = Buffer.concat([buffer, chunk]);
  let end;
  while ((end = buffer.indexOf(0)) >= 0) {
    const msg = JSON.parse(buffer.subarray(0, end).toString("utf8"));
    buffer = buffer.subarray(end + 1);
    if (msg.id && pending.has(msg.id)) {
      const { resolve, reject } = pending.get(msg.id);
      pending.delete(msg.id);
      msg.error ? reject(new Error(JSON.stringify(msg.error))) : resolve(msg.result);
    } else if (msg.method) {
      for (const w of waiters.splice(0)) {
        if (w.method === msg.method && w.sessionId === msg.sessionId) w.resolve(msg.params);
        else waiters.push(w);
      }
    }
  }
});
function send(method, params = {}, sessionId) {
  const id = nextId++;
  toChrome.write(JSON.stringify({ id, method, params, ...(sessionId ? { sessionId } : {}) }) + "\0");
  return new Promise((resolve, reject) => pending.set(id, { resolve, reject }));
}
function event(method, sessionId) {
  return new Promise((resolve) => waiters.push({ method, sessionId, resolve }));
}

// A link or image source: relative (no scheme, no leading slash), and the file it names exists
// inside the export folder.
function checkRef(ref) {
  if (ref.startsWith("#")) return null;
  if (/^[a-z][a-z0-9+.-]*:/i.test(ref) || ref.startsWith("/") || ref.startsWith("\\")) return `${ref}: not relative`;
  const file = path.resolve(root, decodeURIComponent(ref.split("#")[0].split("?")[0]));
  if (!file.startsWith(root + path.sep)) return `${ref}: outside the export folder`;
  if (!fs.existsSync(file)) return `${ref}: no such file`;
  return null;
}

try {
  const { targetId } = await send("Target.createTarget", { url: "about:blank" });
  const { sessionId } = await send("Target.attachToTarget", { targetId, flatten: true });
  await send("Page.enable", {}, sessionId);
  const loaded = event("Page.loadEventFired", sessionId);
  await send("Page.navigate", { url: pathToFileURL(index).href }, sessionId);
  await loaded;
  const { result } = await send("Runtime.evaluate", {
    returnByValue: true,
    expression: `(() => ({
      title: document.title,
      images: [...document.images].map((i) => ({src: i.getAttribute("src"), complete: i.complete, naturalWidth: i.naturalWidth, naturalHeight: i.naturalHeight})),
      links: [...document.querySelectorAll("a[href]")].map((a) => a.getAttribute("href")),
      scripts: document.scripts.length,
      resources: performance.getEntriesByType("resource").map((r) => r.name),
      height: Math.ceil(document.documentElement.scrollHeight),
      headings: [...document.querySelectorAll("h1, h2")].map((h) => h.textContent),
    }))()`,
  }, sessionId);
  const page = result.value;
  const problems = [];
  for (const img of page.images) {
    if (!img.complete || img.naturalWidth === 0) problems.push(`${img.src}: did not load`);
    const p = checkRef(img.src);
    if (p) problems.push(p);
  }
  for (const href of page.links) {
    const p = checkRef(href);
    if (p) problems.push(p);
  }
  for (const r of page.resources) if (!r.startsWith("file:")) problems.push(`${r}: not a local file`);
  if (page.scripts > 0) problems.push(`${page.scripts} script(s) on a static page`);
  const height = Math.min(page.height, 16000);
  await send("Emulation.setDeviceMetricsOverride", { width: 1280, height, deviceScaleFactor: 1, mobile: false }, sessionId);
  const shot = await send("Page.captureScreenshot", { format: "png", captureBeyondViewport: true }, sessionId);
  fs.writeFileSync(path.resolve(shotArg), Buffer.from(shot.data, "base64"));
  finish(problems.length ? 1 : 0, { ...page, problems, screenshot: path.resolve(shotArg), screenshot_size: [1280, height] });
} catch (e) {
  finish(2, { error: String(e && e.stack || e), stderr });
}
