// Load Relevo's exports in CesiumJS (npm `cesium`) inside headless
// Chromium (Debian's, driven by puppeteer-core; WebGL through SwiftShader),
// fly to a region, wait until every tile is loaded, and print one JSON
// object: the errors seen (console, page, failed or refused requests) and,
// per scene, a grid of the view's luminance and green excess; for scenes
// that ask, the heights sampleTerrainMostDetailed gives at the points and
// where points project on the screen.
//
//   node cesium-check.mjs TERRAIN_DIR REQUEST_JSON SCREENSHOT_PNG [TILES_DIR]
//
// REQUEST_JSON: {"view": [lon, lat, height_m, heading_deg, pitch_deg],
//                "points": [[lon, lat], ...],
//                "scenes": [{"name", "terrain": bool, "tilesets": [path in
//                  TILES_DIR, ...], "sample": bool, "project": [[lon, lat,
//                  metres above the terrain], ...], "screenshot": bool or
//                  a path}, ...]}
// Without "scenes": the terrain ("relevo", sampled, the screenshot) and
// the bare ellipsoid ("ellipsoid").
import { createServer } from "node:http";
import { readFileSync, statSync } from "node:fs";
import { extname, join, normalize } from "node:path";
import { fileURLToPath } from "node:url";
import puppeteer from "puppeteer-core";

const [terrainDir, pointsPath, screenshotPath, tilesDir] = process.argv.slice(2);
const request = JSON.parse(readFileSync(pointsPath, "utf8"));
const scenes = request.scenes ?? [
  { name: "relevo", terrain: true, sample: true, screenshot: true },
  { name: "ellipsoid", terrain: false },
];
const cesiumDir = fileURLToPath(new URL("./node_modules/cesium/Build/Cesium/", import.meta.url));
const types = {
  ".js": "text/javascript", ".json": "application/json", ".css": "text/css",
  ".png": "image/png", ".svg": "image/svg+xml", ".wasm": "application/wasm",
  ".terrain": "application/vnd.quantized-mesh", ".glb": "model/gltf-binary",
};

const page = `<!doctype html><html><head><meta charset="utf-8">
<style>html,body,#c{margin:0;width:100%;height:100%;overflow:hidden}</style>
<script>window.CESIUM_BASE_URL = "/cesium/";</script>
<script src="/cesium/Cesium.js"></script>
<link rel="stylesheet" href="/cesium/Widgets/widgets.css"></head>
<body><div id="c"></div></body></html>`;

function serve(root, path, res) {
  const file = normalize(join(root, decodeURIComponent(path)));
  if (!file.startsWith(normalize(root))) return false;
  try {
    if (!statSync(file).isFile()) return false;
  } catch {
    return false;
  }
  res.writeHead(200, { "Content-Type": types[extname(file)] ?? "application/octet-stream" });
  res.end(readFileSync(file));
  return true;
}

const server = createServer((req, res) => {
  const path = new URL(req.url, "http://localhost").pathname;
  if (path === "/favicon.ico") {
    res.writeHead(204);
    res.end();
    return;
  }
  if (path === "/") {
    res.writeHead(200, { "Content-Type": "text/html" });
    res.end(page);
    return;
  }
  const served = path.startsWith("/cesium/")
    ? serve(cesiumDir, path.slice("/cesium/".length), res)
    : path.startsWith("/terrain/") ? serve(terrainDir, path.slice("/terrain/".length), res)
    : path.startsWith("/tiles/") && tilesDir && serve(tilesDir, path.slice("/tiles/".length), res);
  if (!served) {
    res.writeHead(404);
    res.end();
  }
});
await new Promise((resolve) => server.listen(0, "127.0.0.1", resolve));
const base = `http://127.0.0.1:${server.address().port}`;

const browser = await puppeteer.launch({
  executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
  headless: true,
  args: ["--headless=new", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    "--no-sandbox", "--ignore-gpu-blocklist", "--window-size=960,540"],
  defaultViewport: { width: 960, height: 540 },
  protocolTimeout: 300000,
});
const errors = [];
const result = { errors };
try {
  for (const scene of scenes) {
    const tab = await browser.newPage();
    tab.on("console", (m) => { if (m.type() === "error") errors.push(`console: ${m.text()}`); });
    tab.on("pageerror", (e) => errors.push(`page: ${e.message}`));
    tab.on("requestfailed", (r) => errors.push(`request failed: ${r.url()}`));
    tab.on("response", (r) => { if (r.status() >= 400) errors.push(`HTTP ${r.status()}: ${r.url()}`); });
    await tab.goto(base + "/", { waitUntil: "load" });
    const seen = await tab.evaluate(async (wanted, request) => {
      const C = window.Cesium;
      const provider = wanted.terrain
        ? await C.CesiumTerrainProvider.fromUrl("/terrain/", { requestVertexNormals: true, requestWaterMask: true })
        : new C.EllipsoidTerrainProvider();
      const viewer = new C.Viewer("c", {
        baseLayer: false, terrainProvider: provider, animation: false, timeline: false,
        geocoder: false, homeButton: false, sceneModePicker: false, baseLayerPicker: false,
        navigationHelpButton: false, fullscreenButton: false, infoBox: false,
        selectionIndicator: false, contextOptions: { webgl: { preserveDrawingBuffer: true } },
      });
      const scene = viewer.scene;
      // Grey ground lit from the east, low over the horizon, so that
      // slopes shade apart; the same light for every run.
      scene.globe.baseColor = new C.Color(0.55, 0.55, 0.55, 1.0);
      scene.globe.enableLighting = true;
      scene.globe.dynamicAtmosphereLighting = false;
      const [lon0, lat0] = request.view;
      const frame = C.Transforms.eastNorthUpToFixedFrame(C.Cartesian3.fromDegrees(lon0, lat0));
      const axis = (k) => C.Cartesian3.fromElements(frame[4 * k], frame[4 * k + 1], frame[4 * k + 2]);
      const towardLight = C.Cartesian3.add(
        C.Cartesian3.multiplyByScalar(axis(0), 0.94, new C.Cartesian3()),
        C.Cartesian3.multiplyByScalar(axis(2), 0.34, new C.Cartesian3()),
        new C.Cartesian3(),
      );
      scene.light = new C.DirectionalLight({
        direction: C.Cartesian3.normalize(C.Cartesian3.negate(towardLight, new C.Cartesian3()), new C.Cartesian3()),
      });
      scene.globe.showGroundAtmosphere = false;
      scene.skyAtmosphere.show = false;
      scene.skyBox.show = false;
      scene.sun.show = false;
      scene.moon.show = false;
      scene.fog.enabled = false;
      viewer.clock.shouldAnimate = false;
      const [lon, lat, h, heading, pitch] = request.view;
      viewer.camera.setView({
        destination: C.Cartesian3.fromDegrees(lon, lat, h),
        orientation: { heading: C.Math.toRadians(heading), pitch: C.Math.toRadians(pitch), roll: 0 },
      });
      const tilesets = [];
      for (const path of wanted.tilesets ?? []) {
        const tileset = await C.Cesium3DTileset.fromUrl("/tiles/" + path);
        tileset.tileFailed.addEventListener((e) => console.error(`tile failed: ${e.url}: ${e.message}`));
        scene.primitives.add(tileset);
        tilesets.push(tileset);
      }
      // Every tile loaded, for 20 frames in a row (at most 300 s: SwiftShader
      // in Chromium 156 takes over 90 s for the 3D Tiles scenes on 2 cores).
      const start = performance.now();
      let settled = 0;
      while (settled < 20 && performance.now() - start < 300000) {
        await new Promise((r) => requestAnimationFrame(r));
        const loaded = scene.globe.tilesLoaded && tilesets.every((t) => t.tilesLoaded);
        settled = loaded ? settled + 1 : 0;
      }
      const loaded = settled >= 20;
      scene.render();
      // Luminance on a 96 × 54 grid of the canvas.
      const canvas = scene.canvas;
      const small = document.createElement("canvas");
      small.width = 96; small.height = 54;
      const ctx = small.getContext("2d");
      ctx.drawImage(canvas, 0, 0, 96, 54);
      const px = ctx.getImageData(0, 0, 96, 54).data;
      const luminance = [];
      const green = [];
      for (let i = 0; i < px.length; i += 4) {
        luminance.push(Math.round(0.299 * px[i] + 0.587 * px[i + 1] + 0.114 * px[i + 2]));
        green.push(2 * px[i + 1] - px[i] - px[i + 2]);
      }
      // The cells of the same grid that points on the terrain, raised by
      // their third value, fall in (-1: off the view).
      const toProject = wanted.project ?? [];
      const ground = wanted.terrain && toProject.length > 0
        ? await C.sampleTerrainMostDetailed(provider, toProject.map(([x, y]) => C.Cartographic.fromDegrees(x, y)))
        : toProject.map(() => ({ height: 0 }));
      const projected = toProject.map(([x, y, raise], k) => {
        const w = C.SceneTransforms.worldToWindowCoordinates(scene, C.Cartesian3.fromDegrees(x, y, ground[k].height + raise));
        if (!w || w.x < 0 || w.y < 0 || w.x >= canvas.clientWidth || w.y >= canvas.clientHeight) return -1;
        return Math.floor((w.y / canvas.clientHeight) * 54) * 96 + Math.floor((w.x / canvas.clientWidth) * 96);
      });
      let sampled = null;
      if (wanted.sample) {
        const cartographics = request.points.map(([x, y]) => C.Cartographic.fromDegrees(x, y));
        const out = await C.sampleTerrainMostDetailed(provider, cartographics);
        sampled = out.map((c) => c.height);
      }
      return { loaded, luminance, green, projected, sampled, seconds: (performance.now() - start) / 1000 };
    }, scene, request);
    if (!seen.loaded) errors.push(`${scene.name}: tiles still loading after 300 s`);
    console.error(`${scene.name}: ${seen.seconds} s, loaded ${seen.loaded}`);
    result[scene.name] = { luminance: seen.luminance, green: seen.green, projected: seen.projected, seconds: seen.seconds };
    if (seen.sampled) result.sampled = seen.sampled;
    if (scene.screenshot) {
      await tab.screenshot({ path: typeof scene.screenshot === "string" ? scene.screenshot : screenshotPath });
    }
    await tab.close();
  }
} catch (e) {
  errors.push(`driver: ${e.message}`);
} finally {
  await browser.close();
  server.close();
}
console.log(JSON.stringify(result));
