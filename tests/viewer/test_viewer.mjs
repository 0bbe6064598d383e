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
// its chains' units as the chain table has them. Prints the viewer's frame
// times and leaves screenshots of three views in WORK.
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
