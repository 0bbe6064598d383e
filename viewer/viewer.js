// The tigerlod viewer: the server chooses the front for the view (the
// reader runtime's Algorithm 6.1, one implementation: /api/front), the page
// holds the decoded payloads under a byte budget and draws them. Keys: L
// colours by LOD, U shows unit labels, 0 frames the map again.

const budgetBytes = Number(new URLSearchParams(location.search).get("budget_mb") ?? 32) * 1024 * 1024;
const prefetchOn = new URLSearchParams(location.search).get("prefetch") !== "0";
const canvas = document.getElementById("map");
const ctx = canvas.getContext("2d");
const hud = document.getElementById("hud");
const state = { tree: null, cx: 0, cy: 0, upp: 1, lodColours: false, labels: true, front: [], draw: [], frameMs: 0,
                hover: null, violations: [], pinned: null };
const cache = new Map(); // "node/lod" -> { geometry, bytes, used }
const units = new Map(); // node -> units payload (JSON)
const tables = new Map(); // node -> chain table (JSON): ids, left, right units
const stats = { loads: 0, evictions: 0, resident: 0, peak: 0, errors: 0, hits: 0, misses: 0, prefetches: 0 };
let prefetching = Promise.resolve();
let clock = 0;

function parseGeometry(buffer) {
  const view = new DataView(buffer);
  const chains = view.getUint32(0, true), points = view.getUint32(4, true);
  const offsets = new Uint32Array(buffer.slice(8, 8 + 4 * (chains + 1)));
  const xy = new Int32Array(buffer.slice(8 + 4 * (chains + 1), 8 + 4 * (chains + 1) + 8 * points));
  return { chains, offsets, xy };
}

function evictFor(bytes, keep) {
  // Least recently used first, never what the current front draws.
  const entries = [...cache.entries()].filter(([k]) => !keep.has(k)).sort((a, b) => a[1].used - b[1].used);
  while (stats.resident + bytes > budgetBytes && entries.length > 0) {
    const [k, e] = entries.shift();
    cache.delete(k);
    stats.resident -= e.bytes;
    stats.evictions++;
  }
  return stats.resident + bytes <= budgetBytes;
}

// Load a payload into the cache, evicting what `keep` does not hold;
// `prefetch` marks a load for the prefetch view (counted apart, and never
// at the cost of what the front draws).
async function load(node, lod, keep, prefetch = false) {
  const key = `${node}/${lod}`;
  if (cache.has(key)) {
    cache.get(key).used = ++clock;
    if (!prefetch) stats.hits++;
    return;
  }
  if (!prefetch) stats.misses++;
  // Its size is known from the tree (/api/node's layout): a prefetch goes
  // only into free room, never evicting anything, so that it cannot thrash
  // under a budget that binds.
  const n = state.tree.nodes[node];
  const size = 8 + 4 * (n.chains + 1) + 8 * n.lods[lod].vertices;
  if (prefetch && stats.resident + size > budgetBytes) return;
  const response = await fetch(`/api/node/${node}/${lod}`);
  if (!response.ok) {
    stats.errors++;
    return;
  }
  const buffer = await response.arrayBuffer();
  if (cache.has(key) || !evictFor(buffer.byteLength, keep)) {
    return;
  }
  cache.set(key, { geometry: parseGeometry(buffer), bytes: buffer.byteLength, used: prefetch ? 0 : ++clock });
  stats.resident += buffer.byteLength;
  stats.peak = Math.max(stats.peak, stats.resident);
  stats.loads++;
  if (prefetch) stats.prefetches++;
}

async function loadUnits(node) {
  if (units.has(node)) return;
  units.set(node, null);
  const response = await fetch(`/api/units/${node}`);
  if (response.ok) units.set(node, await response.json());
}

async function loadTable(node) {
  if (tables.has(node)) return tables.get(node);
  const response = await fetch(`/api/table/${node}`);
  const t = response.ok ? await response.json() : null;
  tables.set(node, t);
  return t;
}

// The unit under a point of the grid, from what is drawn: the first chain
// segment a ray from the point to the east crosses, and the side of it the
// point is on (a chain has its left and right units; the map's chains bound
// every unit). Exact for the drawn LOD, which keeps every unit's point inside.
function unitAt(gx, gy) {
  let best = null;
  for (const [node, lod] of state.front) {
    const e = cache.get(`${node}/${lod}`), t = tables.get(node);
    if (!e || !t) continue;
    const { chains, offsets, xy } = e.geometry;
    for (let c = 0; c < chains; c++) {
      for (let i = offsets[c]; i + 1 < offsets[c + 1]; i++) {
        const ax = xy[2 * i], ay = xy[2 * i + 1], bx = xy[2 * i + 2], by = xy[2 * i + 3];
        if ((ay > gy) === (by > gy)) continue;
        const x = ax + ((gy - ay) * (bx - ax)) / (by - ay);
        if (x < gx || (best && x >= best.x)) continue;
        // Going up (north), the point to the west of the segment is on its left.
        best = { x, unit: by > ay ? t.left[c] : t.right[c], node };
      }
    }
  }
  return best && best.unit ? best : null;
}

function frame() {
  // Where most of the map is (the server's reader::main_extent).
  const root = state.tree.frame;
  state.cx = (root[0] + root[2]) / 2;
  state.cy = (root[1] + root[3]) / 2;
  state.upp = Math.max((root[2] - root[0]) / canvas.width, (root[3] - root[1]) / canvas.height) * 1.05;
}

let pending = null, again = false;
function update() {
  // One front request at a time; a view change meanwhile asks again after
  // it, and whoever waits resolves once the front of the latest view is drawn.
  if (pending) {
    again = true;
    return pending;
  }
  pending = (async () => {
    do {
      again = false;
      await fetchFront();
    } while (again);
    pending = null;
  })();
  return pending;
}

async function fetchFront() {
  const w = canvas.width, h = canvas.height;
  const q = `cx=${state.cx}&cy=${state.cy}&upp=${state.upp}&w=${w}&h=${h}`;
  const response = await fetch(`/api/front?${q}`);
  const { front, draw: drawList } = await response.json();
  const keep = new Set(front.map(([n, k]) => `${n}/${k}`));
  await Promise.all(front.map(([n, k]) => load(n, k, keep)));
  await Promise.all(front.map(([n]) => loadTable(n)));
  if (state.labels) await Promise.all(front.map(([n]) => loadUnits(n)));
  state.front = front;
  state.draw = drawList;
  draw();
  // Prefetch: the fronts of the four views half a screen away (east,
  // west, north, south) at this scale and size, loaded after the front is
  // drawn and only into room the current front does not need (prefetched
  // payloads are the first evicted), so that a pan finds them resident.
  const views = [[w / 2, 0], [-w / 2, 0], [0, h / 2], [0, -h / 2]].map(([dx, dy]) =>
    `cx=${state.cx + dx * state.upp}&cy=${state.cy + dy * state.upp}&upp=${state.upp}&w=${w}&h=${h}`);
  prefetching = (async () => {
    for (const q of prefetchOn ? views : []) {
      for (const [n, k] of (await (await fetch(`/api/front?${q}`)).json()).front) {
        if (!keep.has(`${n}/${k}`)) await load(n, k, keep, true);
        await loadTable(n);
      }
    }
  })();
}

const lodPalette = ["#000000", "#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e", "#e6ab02", "#a6761d"];

function draw() {
  const t0 = performance.now();
  const w = canvas.width, h = canvas.height;
  ctx.clearRect(0, 0, w, h);
  const sx = (x) => (x - state.cx) / state.upp + w / 2;
  const sy = (y) => h / 2 - (y - state.cy) / state.upp;
  // What the server's draw list says (reader::draw_list: each chain once,
  // a border between levels by the finer node), border level by level from
  // the finest up, each in its style (reader::line_style): as
  // tigerlod-render draws the same view.
  const styles = state.tree.styles;
  let deepest = 0;
  for (const d of state.draw) for (let i = 1; i < d.length; i += 2) deepest = Math.max(deepest, d[i]);
  ctx.lineCap = "butt";
  for (let level = deepest; level >= 0; level--) {
    const style = styles[Math.min(level, styles.length - 1)];
    ctx.lineWidth = style.width * devicePixelRatio;
    const grey = `rgb(${style.rgb.join(",")})`;
    ctx.strokeStyle = grey;
    ctx.beginPath();
    state.front.forEach(([node, lod], item) => {
      const e = cache.get(`${node}/${lod}`);
      const d = state.draw[item];
      if (!e || !d) return;
      const { offsets, xy } = e.geometry;
      if (state.lodColours) {
        ctx.stroke();
        ctx.beginPath();
        ctx.strokeStyle = lodPalette[lod % lodPalette.length];
      }
      for (let j = 0; j < d.length; j += 2) {
        if (d[j + 1] !== level) continue;
        const c = d[j];
        for (let i = offsets[c]; i < offsets[c + 1]; i++) {
          const x = sx(xy[2 * i]), y = sy(xy[2 * i + 1]);
          if (i === offsets[c]) ctx.moveTo(x, y); else ctx.lineTo(x, y);
        }
      }
    });
    ctx.stroke();
  }
  ctx.lineWidth = Math.max(1, devicePixelRatio);
  if (state.pinned?.geometry) {
    // The chains of the violation clicked, at its LOD, over the map.
    const { item, geometry, table } = state.pinned;
    ctx.strokeStyle = "#d7191c";
    ctx.lineWidth = 3 * devicePixelRatio;
    ctx.beginPath();
    for (let c = 0; c < geometry.chains; c++) {
      if (!item.chains.includes(table.ids[c])) continue;
      for (let i = geometry.offsets[c]; i < geometry.offsets[c + 1]; i++) {
        const x = sx(geometry.xy[2 * i]), y = sy(geometry.xy[2 * i + 1]);
        if (i === geometry.offsets[c]) ctx.moveTo(x, y); else ctx.lineTo(x, y);
      }
    }
    ctx.stroke();
    ctx.lineWidth = Math.max(1, devicePixelRatio);
  }
  for (const v of state.violations) {
    ctx.fillStyle = v.kind === "input_problem" ? "rgba(120,120,120,0.8)" : "rgba(215,25,28,0.9)";
    ctx.beginPath();
    ctx.arc(sx(v.x), sy(v.y), 4 * devicePixelRatio, 0, 2 * Math.PI);
    ctx.fill();
  }
  if (state.labels) {
    // Each unit's name (or code) at its internal point, once few enough are in view to read.
    const shown = [];
    for (const [node] of state.front) {
      for (const unit of units.get(node)?.units ?? []) {
        const x = sx(unit.point[0]), y = sy(unit.point[1]);
        if (x >= 0 && y >= 0 && x <= w && y <= h) shown.push([unit.name || unit.code, x, y]);
      }
    }
    if (shown.length <= 150) {
      ctx.fillStyle = "#7a2e0e";
      ctx.font = `${11 * devicePixelRatio}px system-ui, sans-serif`;
      ctx.textAlign = "center";
      for (const [text, x, y] of shown) ctx.fillText(text, x, y);
    }
  }
  state.frameMs = performance.now() - t0;
  const lods = state.front.map(([, k]) => k);
  hud.textContent =
    `frame ${state.frameMs.toFixed(1)} ms   front ${state.front.length} nodes (LODs ${Math.min(...lods)}-${Math.max(...lods)})\n` +
    `resident ${(stats.resident / 1048576).toFixed(2)} of ${(budgetBytes / 1048576).toFixed(0)} MiB   ` +
    `loads ${stats.loads} (${stats.prefetches} prefetched)   hits ${stats.hits}   misses ${stats.misses}   ` +
    `evictions ${stats.evictions}   errors ${stats.errors}\n` +
    `L: colour by LOD (${state.lodColours ? "on" : "off"})   U: labels   0: frame the map` +
    (state.hover ? `\nunit ${state.hover.code}${state.hover.name ? " " + state.hover.name : ""}` : "") +
    (state.pinned ? `\n${state.pinned.item.kind} at LOD ${state.pinned.item.lod} (${state.pinned.item.level} ${state.pinned.item.node}): ` +
      `chains ${state.pinned.item.chains.join(", ")}; ${state.pinned.units}\n${state.pinned.item.detail}` : "") +
    (state.violations.length ? `\n${state.violations.length} report items (click one)` : "");
  // A scale bar in projected metres (the grid's), about 120 px long.
  const metres = 120 * state.upp * state.tree.grid_m;
  const nice = Math.pow(10, Math.floor(Math.log10(metres)));
  const length = [5, 2, 1].map((m) => m * nice).find((m) => m <= metres) ?? nice;
  document.getElementById("bar").style.width = `${length / (state.upp * state.tree.grid_m) / devicePixelRatio}px`;
  document.getElementById("label").textContent = length >= 1000 ? `${length / 1000} km` : `${length} m`;
  window.tigerlodStats = { ...stats, budget: budgetBytes, front: state.front, frameMs: state.frameMs,
                           hover: state.hover, pinned: state.pinned ? state.pinned.item : null };
}

function resize() {
  canvas.width = innerWidth * devicePixelRatio;
  canvas.height = innerHeight * devicePixelRatio;
}

let drag = null;
canvas.addEventListener("mousedown", (e) => { drag = { x: e.clientX, y: e.clientY }; });
addEventListener("mouseup", () => { drag = null; });
function toGrid(clientX, clientY) {
  return [state.cx + (clientX * devicePixelRatio - canvas.width / 2) * state.upp,
          state.cy + (canvas.height / 2 - clientY * devicePixelRatio) * state.upp];
}

async function hoverAt(clientX, clientY) {
  const [gx, gy] = toGrid(clientX, clientY);
  const hit = unitAt(gx, gy);
  if (!hit) {
    state.hover = null;
  } else {
    await loadUnits(hit.node);
    const u = units.get(hit.node)?.units.find((x) => x.code === hit.unit);
    state.hover = { code: hit.unit, name: u?.name ?? "" };
  }
  draw();
  return state.hover;
}

// Fly to a report item and show its chains at its LOD, with their units.
async function pin(item) {
  const node = state.tree.nodes.findIndex((n, i) => (i === 0 ? item.node === "root" : n.code === item.node) &&
                                          state.tree.levels[n.level] === item.level);
  state.cx = item.x;
  state.cy = item.y;
  state.upp = Math.max(state.tree.lod_eps_m[item.lod] || 100, 100) / state.tree.grid_m / 20;
  state.pinned = { item, geometry: null, table: null, units: "" };
  if (node >= 0) {
    const [g, t] = await Promise.all([fetch(`/api/node/${node}/${item.lod}`), loadTable(node)]);
    if (g.ok && t) {
      state.pinned.geometry = parseGeometry(await g.arrayBuffer());
      state.pinned.table = t;
      state.pinned.units = item.chains.map((id) => {
        const c = t.ids.indexOf(id);
        return c < 0 ? `${id}: not in node` : `${t.left[c] || "-"} | ${t.right[c] || "-"}`;
      }).join("; ");
    }
  }
  await update();
  return state.pinned.item;
}

canvas.addEventListener("click", (e) => {
  const hit = state.violations.find((v) => {
    const dx = (v.x - state.cx) / state.upp + canvas.width / 2 - e.clientX * devicePixelRatio;
    const dy = canvas.height / 2 - (v.y - state.cy) / state.upp - e.clientY * devicePixelRatio;
    return dx * dx + dy * dy <= 64 * devicePixelRatio * devicePixelRatio;
  });
  if (hit) pin(hit);
});

let hoverTimer = null;
addEventListener("mousemove", (e) => {
  if (!drag) {
    clearTimeout(hoverTimer);
    hoverTimer = setTimeout(() => hoverAt(e.clientX, e.clientY), 30);
    return;
  }
  state.cx -= (e.clientX - drag.x) * devicePixelRatio * state.upp;
  state.cy += (e.clientY - drag.y) * devicePixelRatio * state.upp;
  drag = { x: e.clientX, y: e.clientY };
  draw();
  update();
});
canvas.addEventListener("wheel", (e) => {
  e.preventDefault();
  const f = Math.exp(e.deltaY * 0.002);
  const px = (e.clientX * devicePixelRatio - canvas.width / 2) * state.upp;
  const py = (canvas.height / 2 - e.clientY * devicePixelRatio) * state.upp;
  state.cx += px * (1 - f);
  state.cy += py * (1 - f);
  state.upp *= f;
  draw();
  update();
}, { passive: false });
addEventListener("keydown", (e) => {
  if (e.key === "l" || e.key === "L") state.lodColours = !state.lodColours;
  if (e.key === "u" || e.key === "U") state.labels = !state.labels;
  if (e.key === "0") frame();
  draw();
  update();
});
addEventListener("resize", () => { resize(); draw(); update(); });

// For scripted use (tests, a camera path): fly to a view and wait for it;
// the unit at a point of the page; fly to report item i.
window.tigerlodHover = (clientX, clientY) => hoverAt(clientX, clientY);
window.tigerlodIdle = async () => {
  // Until no front request is in flight and the latest prefetching is done.
  for (;;) {
    const p = pending, q = prefetching;
    await p;
    await q;
    if (p === pending && q === prefetching && !pending) return { ...stats };
  }
};
window.tigerlodPin = (i) => pin(state.violations[i]);
window.tigerlodView = async (cx, cy, upp) => {
  state.cx = cx; state.cy = cy; state.upp = upp;
  await update();
  return window.tigerlodStats;
};

resize();
state.tree = await (await fetch("/api/tree")).json();
frame();
// A view in the address (?cx=&cy=&upp=, grid units): a link to a place.
const params = new URLSearchParams(location.search);
if (params.has("cx") && params.has("cy") && params.has("upp")) {
  state.cx = Number(params.get("cx"));
  state.cy = Number(params.get("cy"));
  state.upp = Number(params.get("upp"));
}
if (params.get("lod_colours") === "1") state.lodColours = true;
if (params.get("labels") === "0") state.labels = false;
if (state.tree.verify) {
  const report = await (await fetch("/api/verify")).json();
  state.violations = (report.items ?? []).filter((v) => Number.isFinite(v.x) && Number.isFinite(v.y));
}
await update();
window.tigerlodReady = true;
