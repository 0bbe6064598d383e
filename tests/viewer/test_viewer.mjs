// The viewer in headless chromium (test_viewer.sh starts the server):
//   node test_viewer.mjs PLAYWRIGHT_CORE CHROMIUM BASE_URL WORK
// Along a scripted zoom from the overview to one county, at a budget that
// does not bind and at one that does: no console or page errors; at every
// view the page draws the front the server's reader chooses for that view
// (the same nodes and LODs), something is drawn, and the bytes resident in
// the page never exceed its budget; under the binding budget it evicts.
// The keys L and U work. At the last view, hovering over each unit's
// internal point names that unit. A report item (written into the report
// the server was given) shows as a marker; pinning it flies there and names
// its chains' units as the chain table has them. At three views of
// tigerlod-render's zoom path (WORK/render: its PNGs and the views in its
// CSV) the page draws what tigerlod-render drew: the ink of each within 2
// pixels of the other's, but for a bound. Prints the viewer's frame times
// and leaves screenshots of the views in WORK.
import fs from "node:fs";
import path from "node:path";

const [pwDir, chromiumPath, base, work] = process.argv.slice(2);
const { chromium } = await import(path.join(pwDir, "index.mjs"));
const failures = [];
const fail = (what) => { failures.push(what); console.log(`FAIL: ${what}`); };

const browser = await chromium.launch({ executablePath: chromiumPath, headless: true, args: ["--no-sandbox"] });
const tree = await (await fetch(`${base}/api/tree`)).json();
// The path: from the whole map to the county 51063 (Floyd, Virginia), 8 views.
const root = tree.nodes[0].box;
const state = tree.nodes.find((n) => n.code === "51");
const county = [state.box[0], state.box[1], state.box[2], state.box[3]];
const frameTimes = [];

async function walk(budgetMb, label, prefetch = true) {
  const page = await browser.newPage({ viewport: { width: 900, height: 600 } });
  const errors = [];
  page.on("console", (m) => { if (m.type() === "error") errors.push(m.text()); });
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(`${base}/?budget_mb=${budgetMb}${prefetch ? "" : "&prefetch=0"}`);
  await page.waitForFunction(() => window.tigerlodReady === true, null, { timeout: 30000 });
  const [w, h] = await page.evaluate(() => {
    const c = document.getElementById("map");
    return [c.width, c.height];
  });
  const start = { cx: (root[0] + root[2]) / 2, cy: (root[1] + root[3]) / 2,
                  upp: Math.max((root[2] - root[0]) / w, (root[3] - root[1]) / h) * 1.05 };
  const end = { cx: (county[0] + county[2]) / 2, cy: (county[1] + county[3]) / 2,
                upp: Math.max((county[2] - county[0]) / w, (county[3] - county[1]) / h) / 6 };
  let last = null;
  for (let i = 0; i < 8; i++) {
    const t = i / 7;
    const v = { cx: start.cx + t * (end.cx - start.cx), cy: start.cy + t * (end.cy - start.cy),
                upp: start.upp * Math.pow(end.upp / start.upp, t) };
    const stats = await page.evaluate(([cx, cy, upp]) => window.tigerlodView(cx, cy, upp), [v.cx, v.cy, v.upp]);
    // Each view's prefetching done before the next view: the same loads in every run.
    await page.evaluate(() => window.tigerlodIdle());
    const want = (await (await fetch(`${base}/api/front?cx=${v.cx}&cy=${v.cy}&upp=${v.upp}&w=${w}&h=${h}`)).json()).front;
    if (JSON.stringify(stats.front) !== JSON.stringify(want)) {
      fail(`${label} view ${i}: the page's front ${JSON.stringify(stats.front)} is not the reader's ${JSON.stringify(want)}`);
    }
    if (stats.resident > stats.budget || stats.peak > stats.budget) {
      fail(`${label} view ${i}: ${stats.resident} bytes resident (peak ${stats.peak}), over the budget ${stats.budget}`);
    }
    const inked = await page.evaluate(() => {
      const c = document.getElementById("map");
      const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
      let n = 0;
      for (let k = 3; k < d.length; k += 4 * 7) n += d[k] > 0 ? 1 : 0;
      return n;
    });
    if (budgetMb >= 1 && inked < 50) {
      fail(`${label} view ${i}: nothing drawn (${inked} inked pixels sampled)`);
    }
    const ms = await page.evaluate(async () => {
      // The frame time of a redraw of the resident front, as the HUD shows it.
      const t0 = performance.now();
      window.dispatchEvent(new KeyboardEvent("keydown", { key: "u" }));
      window.dispatchEvent(new KeyboardEvent("keydown", { key: "u" }));
      return (performance.now() - t0) / 2;
    });
    frameTimes.push(ms);
    if (budgetMb >= 1 && (i === 0 || i === 4 || i === 7)) {
      await page.screenshot({ path: path.join(work, `view-${i}.png`) });
    }
    last = stats;
  }
  if (budgetMb >= 1) {
    // Hover: every unit of the front's nodes whose internal point is in view.
    const view = await page.evaluate(() => ({ dpr: devicePixelRatio }));
    let checked = 0;
    for (const [node] of last.front) {
      const u = await (await fetch(`${base}/api/units/${node}`)).json();
      for (const unit of u.units) {
        const x = ((unit.point[0] - end.cx) / end.upp + w / 2) / view.dpr;
        const y = (h / 2 - (unit.point[1] - end.cy) / end.upp) / view.dpr;
        if (x < 2 || y < 2 || x > w / view.dpr - 2 || y > h / view.dpr - 2) continue;
        const hover = await page.evaluate(([px, py]) => window.tigerlodHover(px, py), [x, y]);
        checked++;
        if (!hover || hover.code !== unit.code || hover.name !== unit.name) {
          fail(`${label}: hovering at unit ${unit.code}'s internal point gives ${JSON.stringify(hover)}`);
        }
      }
    }
    if (checked < 3) fail(`${label}: only ${checked} units in view to hover over`);
    // Prefetching: once it is done, a pan by a quarter screen finds its front resident.
    // (How many loads were prefetches depends on which of the page's own
    // requests finishes first; that the pan misses nothing does not.)
    const before = await page.evaluate(() => window.tigerlodIdle());
    const panned = await page.evaluate(([cx, cy, upp]) => window.tigerlodView(cx, cy, upp),
                                       [end.cx + (w / 4) * end.upp, end.cy, end.upp]);
    if (panned.misses !== before.misses) {
      fail(`${label}: a pan after prefetching missed ${panned.misses - before.misses} payloads`);
    }
    console.log(`${label}: ${before.prefetches} payloads prefetched; a pan then ${panned.hits - before.hits} hits, ` +
                `${panned.misses - before.misses} misses`);
    console.log(`${label}: hover named ${checked} units at their internal points`);
    // A report item on two chains of the state's county map at LOD 2.
    const t = await (await fetch(`${base}/api/table/${tree.nodes.indexOf(state)}`)).json();
    const g = new DataView(await (await fetch(`${base}/api/node/${tree.nodes.indexOf(state)}/2`)).arrayBuffer());
    const chains = g.getUint32(0, true);
    const x0 = g.getInt32(8 + 4 * (chains + 1), true), y0 = g.getInt32(12 + 4 * (chains + 1), true);
    const item = { kind: "crossings", level: "county", lod: 2, node: "51", chains: [t.ids[0], t.ids[1]],
                   x: x0, y: y0, lon: 0, lat: 0, detail: "a test item" };
    fs.writeFileSync(path.join(work, "report.json"), JSON.stringify({ items: [item] }));
    await page.reload();
    await page.waitForFunction(() => window.tigerlodReady === true, null, { timeout: 30000 });
    const pinned = await page.evaluate(() => window.tigerlodPin(0));
    const hud = await page.evaluate(() => document.getElementById("hud").textContent);
    const units = `${t.left[0] || "-"} | ${t.right[0] || "-"}; ${t.left[1] || "-"} | ${t.right[1] || "-"}`;
    if (!pinned || pinned.detail !== "a test item" || !hud.includes(units) || !hud.includes("1 report items")) {
      fail(`${label}: pinning the report item: ${JSON.stringify(pinned)}, HUD ${JSON.stringify(hud)}, want ${units}`);
    }
    await page.screenshot({ path: path.join(work, "view-pinned.png") });
  }
  await page.keyboard.press("L");
  await page.keyboard.press("U");
  await page.keyboard.press("0");
  await page.waitForTimeout(200);
  if (errors.length > 0) fail(`${label}: console or page errors: ${errors.join("; ")}`);
  await page.close();
  return last;
}

// The page against tigerlod-render at the same views: their lines are
// drawn by different rasterizers (canvas 2D antialiased strokes, GL quads),
// so pixels are compared as ink (darker than 235 of 255), and a pixel of
// ink counts as matched when the other image has ink within 2 pixels. Both
// ways at most 2 % unmatched, and the masses of ink (darkness summed) within
// 10 % of each other: the same widths and greys by border level (the
// page drawing every chain in one style, as it did before it took
// tigerlod-render's, was 46 % and 25 % under).
async function compareWithRender() {
  const page = await browser.newPage({ viewport: { width: 900, height: 600 }, deviceScaleFactor: 1 });
  const errors = [];
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(`${base}/?prefetch=0&labels=0`);
  await page.waitForFunction(() => window.tigerlodReady === true, null, { timeout: 30000 });
  const csv = fs.readFileSync(path.join(work, "render", "frames-ooc-noprefetch.csv"), "utf8").trim().split("\n");
  const head = csv[0].split(",");
  const col = (name) => head.indexOf(name);
  for (const f of [0, 10, 20]) {
    const row = csv[1 + f].split(",");
    const [cx, cy, upp] = ["center_x", "center_y", "units_per_pixel"].map((n) => Number(row[col(n)]));
    await page.evaluate(([x, y, u]) => window.tigerlodView(x, y, u), [cx, cy, upp]);
    const png = fs.readFileSync(path.join(work, "render", "frames", `ooc-noprefetch-${String(f).padStart(5, "0")}.png`));
    const r = await page.evaluate(async (dataUrl) => {
      const c = document.getElementById("map");
      const w = c.width, h = c.height;
      const img = new Image();
      img.src = dataUrl;
      await img.decode();
      const o = new OffscreenCanvas(w, h);
      const octx = o.getContext("2d");
      octx.fillStyle = "#ffffff";
      octx.fillRect(0, 0, w, h);
      octx.drawImage(img, 0, 0);
      const want = octx.getImageData(0, 0, w, h).data;
      const got = c.getContext("2d").getImageData(0, 0, w, h).data;
      // Ink: luminance below 235; the page's canvas is composited on white.
      // Its mass: the darkness summed (255 - luminance, over 255), which an
      // antialiased line spreads over more pixels but keeps.
      const inkOf = (d, premul) => {
        const ink = new Uint8Array(w * h);
        let mass = 0;
        for (let i = 0; i < w * h; i++) {
          const a = premul ? d[4 * i + 3] / 255 : 1;
          const lum = (0.299 * d[4 * i] + 0.587 * d[4 * i + 1] + 0.114 * d[4 * i + 2]) * a + 255 * (1 - a);
          ink[i] = lum < 235 ? 1 : 0;
          mass += (255 - lum) / 255;
        }
        return { ink, mass };
      };
      const A = inkOf(want, false), B = inkOf(got, true);
      const a = A.ink, b = B.ink;
      const near = (ink, x, y) => {
        for (let dy = -2; dy <= 2; dy++) {
          for (let dx = -2; dx <= 2; dx++) {
            const X = x + dx, Y = y + dy;
            if (X >= 0 && Y >= 0 && X < w && Y < h && ink[Y * w + X]) return true;
          }
        }
        return false;
      };
      let inkA = 0, inkB = 0, missA = 0, missB = 0;
      for (let y = 0; y < h; y++) {
        for (let x = 0; x < w; x++) {
          const i = y * w + x;
          if (a[i]) { inkA++; if (!near(b, x, y)) missA++; }
          if (b[i]) { inkB++; if (!near(a, x, y)) missB++; }
        }
      }
      return { w, h, inkA, inkB, missA, missB, massA: A.mass, massB: B.mass };
    }, `data:image/png;base64,${png.toString("base64")}`);
    await page.screenshot({ path: path.join(work, `view-render-${f}.png`) });
    const lost = r.missA / Math.max(1, r.inkA), extra = r.missB / Math.max(1, r.inkB);
    console.log(`render frame ${f}: ${r.w}x${r.h}, ink ${r.inkA} pixels, mass ${r.massA.toFixed(0)} (render) / ` +
                `${r.inkB} pixels, mass ${r.massB.toFixed(0)} (page); ` +
                `render's ink the page lacks ${(100 * lost).toFixed(2)} %, the page's the render lacks ${(100 * extra).toFixed(2)} %`);
    if (r.w !== 900 || r.h !== 600) fail(`render frame ${f}: the page's canvas is ${r.w}x${r.h}, not 900x600`);
    if (r.inkA < 1000) fail(`render frame ${f}: tigerlod-render drew almost nothing (${r.inkA} pixels of ink)`);
    if (lost > 0.02 || extra > 0.02) fail(`render frame ${f}: the page and tigerlod-render differ (${(100 * lost).toFixed(2)} %, ${(100 * extra).toFixed(2)} %)`);
    if (r.massB < 0.9 * r.massA || r.massB > 1.1 * r.massA) {
      fail(`render frame ${f}: ink mass ${r.massB.toFixed(0)} in the page, ${r.massA.toFixed(0)} in the render`);
    }
  }
  if (errors.length > 0) fail(`render comparison: page errors: ${errors.join("; ")}`);
  await page.close();
}
await compareWithRender();

const loose = await walk(32, "32 MiB");
console.log(`32 MiB budget: ${loose.loads} loads, ${loose.evictions} evictions, peak ${loose.peak} bytes`);
// A budget that binds: about a tenth of what the walk needed.
const tight = Math.max(loose.peak / 10, 4096) / (1024 * 1024);
const bound = await walk(tight, `${(tight * 1024).toFixed(0)} KiB`);
console.log(`${(tight * 1024).toFixed(0)} KiB budget: ${bound.loads} loads, ${bound.evictions} evictions, peak ${bound.peak} bytes`);
if (bound.evictions === 0) fail("under the binding budget the page never evicted");
// Prefetching must not thrash under it: at most 1.5 times the loads without.
const plain = await walk(tight, "no prefetch", false);
console.log(`${(tight * 1024).toFixed(0)} KiB budget without prefetching: ${plain.loads} loads`);
if (bound.loads > 1.5 * plain.loads) fail(`under the binding budget prefetching made ${bound.loads} loads, ${plain.loads} without`);
frameTimes.sort((a, b) => a - b);
console.log(`viewer frame times (ms): median ${frameTimes[frameTimes.length >> 1].toFixed(2)}, max ${frameTimes.at(-1).toFixed(2)} over ${frameTimes.length} redraws`);
await browser.close();
if (failures.length > 0) process.exit(1);
console.log("viewer: OK");
