// End-to-end test of `chiaro serve` in a real headless browser (Debian's
// chromium driven by playwright-core). Usage, from the repository root:
//   node crates/chiaro-serve/e2e/e2e.mjs [OUT_DIR]
// Environment: CHIARO_SERVE (a command serving SCENE: default
// target/release/chiaro serve if it exists, else target/release/examples/serve),
// CHIARO_CLI (default target/release/chiaro), CHROMIUM (default /usr/bin/chromium).
import { spawn, spawnSync } from "node:child_process";
import { existsSync, mkdirSync, readFileSync } from "node:fs";
import { join, resolve } from "node:path";

const root = resolve(process.cwd());
const out = resolve(process.argv[2] || "/tmp/chiaro-e2e");
mkdirSync(out, { recursive: true });
const scene = join(root, "scenes/cornell-box.toml");
const chromiumPath = process.env.CHROMIUM || "/usr/bin/chromium";
const cli = process.env.CHIARO_CLI || join(root, "target/release/chiaro");
let passed = 0, failed = 0;

function check(name, ok, detail) {
  if (ok) { passed++; console.log(`ok   ${name} ${detail ?? ""}`); }
  else { failed++; console.log(`FAIL ${name} ${detail ?? ""}`); }
}

if (!existsSync(chromiumPath)) {
  console.log(`SKIP: ${chromiumPath} is not installed (apt-get install chromium); the browser test did not run`);
  process.exit(0);
}
const { chromium } = await import("playwright-core");

function serverCommand() {
  if (process.env.CHIARO_SERVE) return process.env.CHIARO_SERVE.split(" ");
  if (existsSync(cli) && spawnSync(cli, ["serve", "--help"]).status === 0) return [cli, "serve"];
  return [join(root, "target/release/examples/serve")];
}

// Start the server on a free port (port 0) and read the URL it prints.
const [cmd, ...pre] = serverCommand();
const server = spawn(cmd, [...pre, scene, "--port", "0"], { stdio: ["ignore", "inherit", "pipe"] });
const url = await new Promise((res, rej) => {
  let buf = "";
  const t = setTimeout(() => rej(new Error(`no URL from the server in 60 s: ${buf}`)), 60000);
  server.stderr.on("data", (d) => {
    buf += d; process.stderr.write(d);
    const m = buf.match(/http:\/\/[0-9.]+:[0-9]+\//);
    if (m) { clearTimeout(t); res(m[0]); }
  });
  server.on("exit", (c) => rej(new Error(`server exited with ${c}: ${buf}`)));
});
console.log(`server at ${url}`);

const browser = await chromium.launch({ executablePath: chromiumPath, headless: true,
  args: ["--no-sandbox", "--disable-gpu"] });
try {
  const page = await browser.newPage({ viewport: { width: 1400, height: 900 } });
  page.on("console", (m) => console.log(`page: ${m.text()}`));
  const t0 = Date.now();
  await page.goto(url);
  const waitDone = async (after) => {
    await page.waitForFunction((n) => Number(document.body.dataset.doneId || 0) > n &&
      document.getElementById("status").dataset.state === "done", after, { timeout: 120000 });
    return page.evaluate(() => Number(document.body.dataset.doneId));
  };
  let id = await waitDone(0);
  check("first picture arrives", true, `(${Date.now() - t0} ms from navigation)`);
  const sceneTechnique = await page.evaluate(() => window.chiaro.info.technique);
  const firstCap = await page.textContent("#cap-0");
  check("starts on the scene's technique", firstCap.startsWith(sceneTechnique), `(${firstCap})`);
  const pixels = () => page.evaluate(() => {
    const c = document.getElementById("canvas-0");
    return { w: c.width, h: c.height, d: Array.from(c.getContext("2d").getImageData(0, 0, c.width, c.height).data) };
  });
  if (sceneTechnique !== "phong") {
    await page.selectOption("#view-a select[name=technique]", "phong");
    id = await waitDone(id);
  }
  const phong = await pixels();
  const mean = (p) => p.d.reduce((a, v, i) => (i % 4 === 3 ? a : a + v), 0) / (p.w * p.h * 3);
  check("phong picture is not blank", mean(phong) > 10, `(mean ${mean(phong).toFixed(1)})`);
  await page.screenshot({ path: join(out, "page-phong.png") });

  // Orbiting the single phong view for 3 s: the drafts' frame rate in the
  // browser (reported, not asserted: the machine may be loaded), then the
  // refinement when the camera stops.
  {
    const b = await page.locator("#canvas-0").boundingBox();
    const [cx, cy] = [b.x + b.width / 2, b.y + b.height / 2];
    await page.mouse.move(cx, cy);
    await page.mouse.down();
    const t = Date.now();
    for (let i = 1; Date.now() - t < 3000; i++) {
      await page.mouse.move(cx + 40 * Math.sin(i / 10), cy + 10 * Math.cos(i / 10));
      await page.waitForTimeout(16);
    }
    const frames = await page.evaluate(() => window.chiaro.framesMoving);
    const ms = Date.now() - t;
    await page.mouse.up();
    check("single-view drafts while orbiting", frames >= 1,
      `(${frames} phong drafts in ${ms} ms: ${(1000 * frames / ms).toFixed(1)} fps)`);
    const t1 = Date.now();
    id = await waitDone(id);
    const passes = await page.evaluate(() => window.chiaro.pass);
    check("single view refines when the camera stops", passes === 2,
      `(full quality ${Date.now() - t1} ms after release, pass ${passes})`);
    await page.click("#reset-camera");
    id = await waitDone(id);
  }

  await page.selectOption("#view-a select[name=technique]", "whitted");
  id = await waitDone(id);
  const cap = await page.textContent("#cap-0");
  check("caption names whitted", cap.startsWith("whitted"), `(${cap})`);
  const whitted = await pixels();
  // On the all-diffuse Cornell box Whitted at depth 0 equals Phong by
  // design (crates/chiaro/tests), so the change is small: the anti-aliasing
  // and the recursive rays make some pixels differ, not the whole picture.
  let diff = 0, changed = 0;
  for (let p = 0; p < whitted.d.length; p += 4) {
    let m = 0;
    for (let c = 0; c < 3; c++) { const d = Math.abs(whitted.d[p + c] - phong.d[p + c]); diff += d; m = Math.max(m, d); }
    if (m >= 3) changed++;
  }
  diff /= whitted.w * whitted.h * 3;
  check("switching phong -> whitted changes the picture", whitted.w === phong.w && changed >= 50,
    `(${changed} pixels differ by >= 3/255, mean |diff| ${diff.toFixed(2)} / 255)`);
  const shotPath = join(out, "canvas-whitted.png");
  await page.locator("#canvas-0").screenshot({ path: shotPath });
  await page.screenshot({ path: join(out, "page-whitted.png") });

  // A CLI render of the same view, compared loosely with the screenshot.
  const refPath = join(out, "cli-whitted.png");
  const samplesA = await page.inputValue("#view-a input[name=samples]");
  const r = spawnSync(cli, ["render", scene, "-t", "whitted", "--width", String(whitted.w),
    "--height", String(whitted.h), "--samples", String(samplesA), "-o", refPath], { stdio: "inherit" });
  if (r.status !== 0) {
    check("CLI render for the comparison", false, `(${cli} exited ${r.status})`);
  } else {
    const b64 = (p) => readFileSync(p).toString("base64");
    const err = await page.evaluate(async ([a, b]) => {
      const load = async (s) => createImageBitmap(await (await fetch(`data:image/png;base64,${s}`)).blob());
      const [ia, ib] = [await load(a), await load(b)];
      const px = (img) => {
        const c = new OffscreenCanvas(64, 64), g = c.getContext("2d");
        g.drawImage(img, 0, 0, 64, 64);
        return g.getImageData(0, 0, 64, 64).data;
      };
      const [pa, pb] = [px(ia), px(ib)];
      let s = 0;
      for (let i = 0; i < pa.length; i++) if (i % 4 !== 3) s += Math.abs(pa[i] - pb[i]);
      return s / (64 * 64 * 3);
    }, [b64(shotPath), b64(refPath)]);
    check("screenshot matches the CLI render loosely", err < 6, `(mean |diff| ${err.toFixed(2)} / 255 at 64x64)`);
  }

  // Split view: whitted against path, with metrics and a difference image.
  await page.check("#split");
  id = await waitDone(id);
  // The numbers of `chiaro compare`: relMSE and FLIP to rank by.
  const [relmse, flipText, psnr] = await Promise.all(["#m-relmse", "#m-flip", "#m-psnr"].map((s) => page.textContent(s)));
  const flipValue = Number(flipText);
  check("split view shows compare's metrics", Number(relmse) > 0 && flipValue > 0 && flipValue < 1 && /dB|inf/.test(psnr),
    `(relMSE ${relmse}, FLIP ${flipText}, display PSNR ${psnr})`);
  await page.screenshot({ path: join(out, "page-split.png") });

  // Orbit: drag across the left image, then wait for the refined frame.
  const box = await page.locator("#canvas-0").boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  const dragStart = Date.now();
  for (let i = 1; i <= 10; i++) {
    await page.mouse.move(box.x + box.width / 2 + i * 12, box.y + box.height / 2 + i * 3);
    await page.waitForTimeout(60);
  }
  const drafts = await page.evaluate(() => window.chiaro.framesMoving);
  const dragMs = Date.now() - dragStart;
  await page.mouse.up();
  check("drafts are drawn while dragging", drafts >= 1,
    `(${drafts} draft frames of the split view in ${dragMs} ms, ${(1000 * drafts / dragMs).toFixed(1)} fps)`);
  id = await waitDone(id);
  const pass = await page.evaluate(() => window.chiaro.pass);
  check("the still camera is refined in two passes", pass === 2, `(last pass ${pass})`);
  const yaw = await page.evaluate(() => window.chiaro.orbit.yaw);
  const orbited = await pixels();
  let od = 0;
  for (let i = 0; i < orbited.d.length; i++) if (i % 4 !== 3) od += Math.abs(orbited.d[i] - whitted.d[i]);
  od /= orbited.w * orbited.h * 3;
  check("dragging orbits the camera", yaw !== 0 && od > 1.0, `(yaw ${yaw.toFixed(2)}, mean |diff| ${od.toFixed(2)})`);
  await page.screenshot({ path: join(out, "page-orbit.png") });

  // A still for screenshots, at 1280x800: ?still=1 renders full quality once
  // and sets data-ready; the split view with the difference image must fit.
  const still = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  await still.goto(`${url}?still=1&split=1&technique=phong`);
  await still.waitForFunction(() => document.body.dataset.ready === "1", null, { timeout: 120000 });
  const shot = await still.screenshot({ path: join(out, "still-split-1280x800.png") });
  const boxes = {};
  for (const c of ["canvas-0", "canvas-1", "canvas-diff"]) boxes[c] = await still.locator(`#${c}`).boundingBox();
  const inView = (b) => b && b.x >= 0 && b.y >= 0 && b.x + b.width <= 1280 && b.y + b.height <= 800;
  const fmt = (b) => b && [b.x, b.y, b.width, b.height].map(Math.round).join(",");
  const d = boxes["canvas-diff"], m = await still.locator("#metrics").boundingBox();
  check("split view fits 1280x800 with the difference image and the metrics", inView(d) && inView(m),
    `(difference image at ${fmt(d)}, metrics at ${fmt(m)})`);
  // The pictures take the window: the compared views are larger than a
  // third of the width beside the controls (324 px), and what is shown
  // reaches the bottom of the window rather than leaving it empty.
  const a0 = boxes["canvas-0"], a1 = boxes["canvas-1"];
  const bottom = Math.max(...[a0, a1, d, m].map((b) => b.y + b.height));
  check("split view gives the pictures the window", inView(a0) && inView(a1) && a0.width >= 400 && a1.width >= 400 && bottom >= 700,
    `(views ${fmt(a0)} and ${fmt(a1)}, lowest picture or table ends at ${Math.round(bottom)} of 800)`);
  const scrolls = await still.evaluate(() => [document.scrollingElement, document.getElementById("views")]
    .some((e) => e.scrollHeight > e.clientHeight + 1 || e.scrollWidth > e.clientWidth + 1));
  check("the split view needs no scrolling", !scrolls);
  // The screenshot itself shows pictures, not the black placeholder canvas.
  const stats = await still.evaluate(async ([b64, boxes]) => {
    const img = await createImageBitmap(await (await fetch(`data:image/png;base64,${b64}`)).blob());
    const c = new OffscreenCanvas(img.width, img.height), g = c.getContext("2d");
    g.drawImage(img, 0, 0);
    const out = {};
    for (const [name, b] of Object.entries(boxes)) {
      const px = g.getImageData(Math.round(b.x), Math.round(b.y), Math.round(b.width), Math.round(b.height)).data;
      let sum = 0, sq = 0, n = 0;
      for (let i = 0; i < px.length; i += 4) { const v = (px[i] + px[i + 1] + px[i + 2]) / 3; sum += v; sq += v * v; n++; }
      const mean = sum / n;
      out[name] = { mean, sd: Math.sqrt(Math.max(0, sq / n - mean * mean)) };
    }
    return out;
  }, [shot.toString("base64"), boxes]);
  for (const [name, st] of Object.entries(stats)) {
    check(`screenshot shows ${name}`, st.mean > 5 && st.sd > 3, `(mean ${st.mean.toFixed(1)}, sd ${st.sd.toFixed(1)})`);
  }
  const stillStatus = await still.textContent("#status");
  check("the still is not 'rendering'", !/rendering|refining/.test(stillStatus), `(${stillStatus})`);
  // Slider mode: the slider picture (larger than the two side by side),
  // the difference image and the metrics all above the fold.
  await still.check("#slider-mode");
  await still.screenshot({ path: join(out, "still-slider-1280x800.png") });
  const sb = await still.locator("#slider-box").boundingBox();
  const sd = await still.locator("#canvas-diff").boundingBox();
  const sm = await still.locator("#metrics").boundingBox();
  const range = await still.locator("#slider").boundingBox();
  check("slider mode shows the comparison without scrolling", inView(sb) && inView(sd) && inView(sm) && inView(range) && sb.width >= 500,
    `(slider ${fmt(sb)}, difference ${fmt(sd)}, metrics ${fmt(sm)})`);
  await still.close();
} catch (e) {
  check("browser session", false, String(e));
} finally {
  await browser.close();
  server.kill("SIGTERM");
}
console.log(`e2e: ${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
