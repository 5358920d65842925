// opportune dashboard: the runs list (index) and a live run page (run).
// Plain JavaScript, no build step, no library; everything is drawn here from the API's JSON.
// Authentication: a token pasted once, kept in localStorage, sent as a bearer header.
// The event stream (EventSource cannot send headers) is opened with a short-lived ticket.
"use strict";

const TOKEN_KEY = "opportune.token";
const SVG = "http://www.w3.org/2000/svg";

function token() { return localStorage.getItem(TOKEN_KEY); }

function el(tag, attrs, ...children) {
  const e = tag.startsWith("svg:") ? document.createElementNS(SVG, tag.slice(4)) : document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === null || v === undefined || v === false) continue;
    if (k === "class") e.setAttribute("class", v);
    else if (k === "text") e.textContent = v;
    else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v);
  }
  for (const c of children) if (c !== null && c !== undefined) e.append(c);
  return e;
}

class ApiError extends Error {
  constructor(status, body) {
    super((body && body.error && body.error.message) || `HTTP ${status}`);
    this.status = status; this.body = body;
  }
}

async function api(path, options = {}) {
  const headers = Object.assign({ "Accept": "application/json" }, options.headers || {});
  const t = token();
  if (t) headers["Authorization"] = "Bearer " + t;
  const r = await fetch(path, Object.assign({}, options, { headers }));
  let body = null;
  try { body = await r.json(); } catch (e) { body = null; }
  if (!r.ok) throw new ApiError(r.status, body);
  return body;
}

function setupLogin(onReady) {
  const login = document.getElementById("login");
  const form = document.getElementById("login-form");
  const err = document.getElementById("login-error");
  const signout = document.getElementById("signout");
  signout.addEventListener("click", () => { localStorage.removeItem(TOKEN_KEY); location.reload(); });
  form.addEventListener("submit", (ev) => {
    ev.preventDefault();
    localStorage.setItem(TOKEN_KEY, document.getElementById("token").value.trim());
    err.hidden = true;
    login.hidden = true;
    signout.hidden = false;
    onReady();
  });
  if (token()) { signout.hidden = false; onReady(); } else { login.hidden = false; }
  return (message) => {  // call on 401: ask again
    localStorage.removeItem(TOKEN_KEY);
    signout.hidden = true;
    login.hidden = false;
    err.textContent = message; err.hidden = false;
  };
}

const fmtList = (xs) => (xs || []).join(", ");

// Counts are written by the service (Count.text, a listed run's count_text: opportune.policies.printable
// .count_label), in full up to 15 digits and as 6.13e98 past that: the page never formats a count itself,
// so the page and the explanations write every count alike.
const countText = (c) => (c && c.text) || "—";

// ------------------------------------------------------------------ runs list

function initIndex() {
  let timer = null;
  const relogin = setupLogin(() => { refresh(); if (!timer) timer = setInterval(refresh, 2000); });

  async function refresh() {
    try {
      const [{ cells }, { runs }] = await Promise.all([api("/cells"), api("/runs?limit=500")]);
      render(cells, runs);
      document.getElementById("updated").textContent = new Date().toLocaleTimeString();
    } catch (e) {
      if (e.status === 401) { clearInterval(timer); timer = null; relogin("That token was not accepted."); }
    }
  }

  function render(cells, runs) {
    const box = document.getElementById("cells");
    const byCell = new Map(cells.map((c) => [c.name, []]));
    for (const r of runs) { if (!byCell.has(r.cell)) byCell.set(r.cell, []); byCell.get(r.cell).push(r); }
    document.getElementById("empty").hidden = runs.length > 0;
    const sections = [];
    for (const [cell, list] of byCell) {
      const active = list.filter((r) => r.status === "active").length;
      const rows = list.map((r) => {
        const pct = r.progress.units ? (100 * r.progress.installed / r.progress.units) : 0;
        const bar = el("span", { class: "progress" }, el("span"));
        bar.firstChild.style.width = pct.toFixed(1) + "%";
        const tr = el("tr", { class: "run-row", "data-run": r.id, onclick: () => { location.href = `/ui/runs/${r.id}`; } },
          el("td", {}, el("a", { href: `/ui/runs/${r.id}`, text: `#${r.id}` })),
          el("td", { text: r.plan.name || r.plan.id.slice(0, 10) }),
          el("td", { text: r.label || "" }),
          el("td", {}, el("span", { class: `badge ${r.status}`, text: r.status })),
          el("td", { class: "progress-cell" }, bar, `${r.progress.installed}/${r.progress.units}`),
          el("td", { text: r.count_text || "—" }),
          el("td", { text: r.pending || "" }),
          el("td", { class: "muted small", text: new Date(r.updated_at).toLocaleTimeString() }));
        return tr;
      });
      const table = el("table", {},
        el("thead", {}, el("tr", {}, ...["run", "plan", "label", "status", "progress", "sequences left", "pending", "updated"]
          .map((h) => el("th", { text: h })))),
        el("tbody", {}, ...rows));
      sections.push(el("section", { class: "card cell", "data-cell": cell },
        el("h2", {}, `cell ${cell}`, el("span", { class: "muted small", text: `${list.length} runs, ${active} active` })),
        list.length ? table : el("p", { class: "muted", text: "no runs yet" })));
    }
    box.replaceChildren(...sections);
  }
}

// ------------------------------------------------------------------ run page

function initRun() {
  const runId = Number(location.pathname.split("/").filter(Boolean).pop());
  const view = { run: null, rows: [], graph: [], strategy: 0, chosen: false, es: null, seq: -1, retry: null,
                 mode: location.hash === "#full" ? "full" : "frontier", cam: null, moved: false, found: null };
  setupGraphControls();
  window.addEventListener("resize", () => { if (view.run) renderChart(); });  // the chart is drawn to its width
  const relogin = setupLogin(connect);

  // Listening (on) or not (off: reconnecting, offline). A complete run has nothing more to listen for: the
  // pill goes, and the run's status pill says it is complete.
  function setLive(on, text) {
    const live = document.getElementById("live");
    live.className = "live " + (on ? "on" : "off");
    live.textContent = text;
    live.hidden = text === "complete";
  }

  async function connect() {
    clearTimeout(view.retry);
    if (view.es) { view.es.close(); view.es = null; }
    let ticket;
    try {
      ticket = await api(`/runs/${runId}/ticket`, { method: "POST" });
    } catch (e) {
      if (e.status === 401) return relogin("That token was not accepted.");
      if (e.status === 404 || e.status === 422) return showError(`Run ${runId} was not found for this token.`);
      setLive(false, "reconnecting");
      view.retry = setTimeout(connect, 3000);
      return;
    }
    const es = new EventSource(ticket.url);
    view.es = es;
    es.addEventListener("snapshot", (e) => {
      const d = JSON.parse(e.data);
      view.run = d.run; view.rows = d.trace; view.graph = d.graph; view.seq = d.run.seq;
      document.getElementById("run").hidden = false;
      setLive(true, "live");
      renderAll(false);
    });
    for (const kind of ["look", "outcome", "cancel"]) {
      es.addEventListener(kind, (e) => {
        const d = JSON.parse(e.data);
        if (d.seq !== view.seq + 1) return connect();  // a gap: start again from a snapshot
        view.seq = d.seq;
        view.run = d.run;
        if (kind === "cancel") view.rows = view.rows.filter((r) => r.n !== d.cancelled.n || r.outcome !== null);
        else view.rows[d.row.n - 1] = d.row;
        renderAll(true);
      });
    }
    es.addEventListener("closed", () => { es.close(); relogin("The token is no longer valid."); });
    // the run is complete: nothing more will happen to it, so stop listening (no reconnecting)
    es.addEventListener("complete", () => { es.close(); view.es = null; setLive(false, "complete"); });
    es.onerror = () => {  // tickets are short-lived: reconnect with a new one
      es.close();
      setLive(false, "reconnecting");
      view.retry = setTimeout(connect, 2000);
    };
  }

  function showError(message) {
    const err = document.getElementById("error");
    err.textContent = message; err.hidden = false;
    setLive(false, "offline");
  }

  function renderAll(fresh) {
    const run = view.run;
    document.title = `opportune — run ${run.id}`;
    document.getElementById("title").textContent =
      `run #${run.id} · cell ${run.cell} · plan ${run.plan.name}` + (run.label ? ` · ${run.label}` : "");
    const status = document.getElementById("status");
    status.textContent = run.status; status.className = "badge " + run.status;
    renderSummary();
    renderGraph();
    renderCount();
    renderPending();
    renderTrace(fresh);
  }

  function nodeStates(run) {
    const installed = {}, buffered = new Set(run.state.buffered), visible = new Set(run.last_look);
    for (const p of run.state.installed) installed[p] = (installed[p] || 0) + 1;
    const pendingPart = run.pending && run.pending.action.part;
    return { installed, buffered, visible, installable: new Set(run.installable || []), pendingPart };
  }

  // ---------------------------------------------------------------- the precedence graph
  // Two views of one strategy's layout (GET /runs/{id}/graph): the frontier (default) and the full
  // graph. The SVG fills its panel; its viewBox is a camera (centre x, y and scale k in pixels per
  // layout unit) moved by fit, zoom, pan and find, so nothing is re-laid out to move around.

  const NODE_H = 26, MARGIN = 40;
  const FIT_MAX = 1.6, ZOOM_MAX = 8;  // a fit never magnifies a small view past 1.6x
  // The frontier's labels (12 layout units at size 1) are drawn at least LABEL_PX pixels high where the
  // panel allows: the parts grow (up to SIZE_MAX times) while the gaps between them stay, so more of
  // the panel is label. GAP: room for an arrow between two columns; ROW_GAP between two parts of a column.
  const LABEL_PX = 11.5, SIZE_MAX = 2, GAP = 28, ROW_GAP = 30;

  // a part's box at size z (1: the full graph's)
  const nodeWidth = (id, z = 1) => z * Math.min(110, Math.max(44, 12 + 7.2 * id.length));
  const shortId = (id) => (id.length > 14 ? id.slice(0, 13) + "…" : id);

  // The parts that matter now: installable now (from the run, or from this strategy's constraints when
  // the run could not say in time), visible, buffered, pending and partly installed; below them the
  // installed boundary (their installed requirements), above them the next layer (the parts requiring
  // them). When nothing is left to install, the last parts of the plan. O(parts + constraints).
  function frontier(g, s) {
    const quantity = new Map(g.nodes.map((n) => [n.id, n.quantity]));
    const preds = new Map(g.nodes.map((n) => [n.id, []])), succs = new Map(g.nodes.map((n) => [n.id, []]));
    for (const e of g.edges) { preds.get(e.to).push(e.from); succs.get(e.from).push(e.to); }
    const done = (id) => (s.installed[id] || 0) >= quantity.get(id);
    const core = g.nodes.map((n) => n.id).filter((id) => !done(id) && (
      s.installable.has(id) || s.buffered.has(id) || s.visible.has(id) || s.pendingPart === id ||
      (s.installed[id] || 0) > 0 || preds.get(id).every(done)));
    const shown = new Set(core);
    for (const id of core) {
      for (const p of preds.get(id)) if (done(p)) shown.add(p);
      for (const q of succs.get(id)) shown.add(q);
    }
    if (!core.length) for (const n of g.nodes) if (!succs.get(n.id).length) shown.add(n.id);
    return { shown, complete: !core.length };
  }

  // The frontier laid out compactly at label size z: one column per layer that has a part shown (in the
  // full layout's order within the column), a header naming the layer, "⋯" where layers are skipped. A
  // layer taller than the panel allows wraps into several columns, at the number of rows that draws the
  // frontier largest in the panel. O(parts shown x their tallest layer).
  function frontierAt(g, nodes, ids, z) {
    const layers = [...new Set(nodes.map((n) => n.layer))].sort((a, b) => a - b);
    const column = new Map(layers.map((l, k) => [l, k]));
    const columns = layers.map(() => []);
    for (const n of nodes) columns[column.get(n.layer)].push(n);
    // columns as close as the widest part shown allows (room for an arrow between): more fit a screen
    const dx = Math.max(z * 60, GAP + nodes.reduce((m, n) => Math.max(m, nodeWidth(n.id, z)), 0));
    const dy = NODE_H * z + ROW_GAP, top = MARGIN * z;
    const tallest = columns.reduce((m, c) => Math.max(m, c.length), 1);
    const p = panelSize();
    let rows = tallest, best = 0;
    for (let r = tallest; r >= 1; r--) {
      const wide = columns.reduce((m, c) => m + Math.ceil(c.length / r), 0);
      const k = Math.min(p.w / (wide * dx), p.h / (r * dy + 2 * top));
      if (k > best * 1.0001) { best = k; rows = r; }
    }
    const height = Math.min(rows, tallest);
    const placed = [], heads = [];
    let x = top;
    columns.forEach((c, k) => {
      c.sort((a, b) => a.y - b.y || (a.id < b.id ? -1 : 1));
      heads.push({ x, layer: layers[k], skipped: k ? layers[k] - layers[k - 1] - 1 : 0 });
      for (let start = 0; start < c.length; start += rows) {
        const part = c.slice(start, start + rows);
        const offset = (height - part.length) * dy / 2;
        part.forEach((n, i) => placed.push(Object.assign({}, n, { x, y: top + offset + i * dy })));
        x += dx;
      }
    });
    const edges = g.edges.filter((e) => ids.has(e.from) && ids.has(e.to)).map((e) => ({ from: e.from, to: e.to }));
    return { nodes: placed, edges, heads, dx, z, headY: top - NODE_H * z / 2 - 10 * z };
  }

  // The frontier at the smallest label size that draws its labels LABEL_PX high when fitted to the
  // panel, else at the size that draws them largest. O(sizes tried x frontierAt).
  function frontierLayout(g, ids) {
    const nodes = g.nodes.filter((n) => ids.has(n.id)), p = panelSize();
    let best = null;
    for (let z = 1; z <= SIZE_MAX + 1e-9; z += 1 / 12) {
      const lay = frontierAt(g, nodes, ids, z), b = extent(lay);
      lay.labelPx = 12 * z * Math.min(p.w / b.w, p.h / b.h, FIT_MAX);
      if (!best || lay.labelPx > best.labelPx + 1e-6) best = lay;
      if (lay.labelPx >= LABEL_PX) break;
    }
    return best;
  }

  function drawGraph(lay, s, curved) {
    const svg = el("svg:svg", { role: "img", "aria-label": "precedence graph", preserveAspectRatio: "xMidYMid meet" });
    const z = lay.z || 1;
    svg.style.setProperty("--z", z);  // the labels' size (app.css)
    svg.append(el("svg:defs", {}, el("svg:marker", { id: "arrow", viewBox: "0 0 10 10", refX: 10, refY: 5,
      markerWidth: 7, markerHeight: 7, orient: "auto-start-reverse" }, el("svg:path", { d: "M 0 0 L 10 5 L 0 10 z", fill: "#9aa3ad" }))));
    const at = new Map(lay.nodes.map((n) => [n.id, n]));
    // each column's layer: "layer 7" where every header has room beside its neighbours and the "⋯" between
    // them (about 6.6 units a character at size 1), else the number alone after the first column
    const wide = (h) => 6.6 * z * `layer ${h.layer + 1}`.length;
    const roomy = (lay.heads || []).every((h, i) => !i || (wide(h) + wide(lay.heads[i - 1])) / 2 + (h.skipped ? 16 : 6) * z <= lay.dx);
    (lay.heads || []).forEach((h, i) => {
      svg.append(el("svg:text", { class: "layer", x: h.x, y: lay.headY, text: (roomy || !i ? "layer " : "") + (h.layer + 1) }));
      if (h.skipped) svg.append(el("svg:text", { class: "layer", x: h.x - lay.dx / 2, y: lay.headY, text: "⋯" },
                                   el("svg:title", { text: `${h.skipped} layer${h.skipped > 1 ? "s" : ""} not shown` })));
    });
    for (const e of lay.edges) {
      const a = at.get(e.from), b = at.get(e.to);
      const done = (s.installed[e.from] || 0) >= a.quantity;
      const attrs = { class: "edge" + (done ? " done" : ""), "marker-end": "url(#arrow)", "data-edge": `${e.from}>${e.to}` };
      const x1 = a.x + nodeWidth(a.id, z) / 2, x2 = b.x - nodeWidth(b.id, z) / 2;
      if (curved) {  // the frontier's columns are not the layout's: a curve from part to part
        const mx = (x1 + x2) / 2;
        svg.append(el("svg:path", Object.assign(attrs, { d: `M ${x1} ${a.y} C ${mx} ${a.y}, ${mx} ${b.y}, ${x2} ${b.y}` })));
      } else {
        const pts = e.points.map((p) => p.slice());
        pts[0][0] = x1; pts[pts.length - 1][0] = x2;
        svg.append(el("svg:polyline", Object.assign(attrs, { points: pts.map((p) => p.join(",")).join(" ") })));
      }
    }
    for (const n of lay.nodes) svg.append(drawNode(n, s, z));
    return svg;
  }

  function drawNode(n, s, z) {
    const k = s.installed[n.id] || 0, W = nodeWidth(n.id, z), H = NODE_H * z;
    const cls = ["node"];
    let state = "remaining";
    if (k >= n.quantity) { cls.push("installed"); state = "installed"; }
    else {
      if (k > 0) cls.push("partly");
      if (s.installable.has(n.id)) { cls.push("installable"); state = "installable"; }
      if (s.visible.has(n.id)) { cls.push("visible"); state = "visible"; }
      if (s.buffered.has(n.id)) { cls.push("buffered"); state = "buffered"; }
    }
    if (s.pendingPart === n.id) { cls.push("pending"); state = "pending"; }
    if (view.found === n.id) cls.push("found");
    const title = (n.name ? `${n.id} (${n.name})` : n.id) + (n.quantity > 1 ? `: ${k} of ${n.quantity} installed` : `: ${state}`);
    const grp = el("svg:g", { class: cls.join(" "), "data-part": n.id, "data-state": state },
      el("svg:title", { text: title }),
      view.found === n.id ? el("svg:rect", { class: "halo", x: n.x - W / 2 - 6, y: n.y - H / 2 - 6,
                                             width: W + 12, height: H + 12, rx: 10 }) : null,
      el("svg:rect", { x: n.x - W / 2, y: n.y - H / 2, width: W, height: H, rx: 6 * z }),
      el("svg:text", { x: n.x, y: n.y - (n.quantity > 1 ? 4 * z : 0), text: shortId(n.id) }));
    if (n.quantity > 1) grp.append(el("svg:text", { class: "units", x: n.x, y: n.y + 8 * z, text: `${k}/${n.quantity}` }));
    return grp;
  }

  // The drawing's extent in layout units (parts, edges, the frontier's layer headers). O(parts + bends).
  function extent(lay) {
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    const z = lay.z || 1;
    for (const n of lay.nodes) {
      const w = nodeWidth(n.id, z) / 2;
      x0 = Math.min(x0, n.x - w); x1 = Math.max(x1, n.x + w);
      y0 = Math.min(y0, n.y - NODE_H * z / 2); y1 = Math.max(y1, n.y + NODE_H * z / 2);
    }
    if (!lay.nodes.length) return { x: 0, y: 0, w: 100, h: 100 };
    for (const e of lay.edges) {  // the full layout's long edges bend through points beyond the parts
      for (const [x, y] of e.points || []) { x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); }
    }
    if (lay.heads && lay.heads.length) y0 = Math.min(y0, lay.headY - 13 * z);  // the headers' text above them
    const pad = 12;
    return { x: x0 - pad, y: y0 - pad, w: x1 - x0 + 2 * pad, h: y1 - y0 + 2 * pad };
  }

  function panelSize() {
    const box = document.getElementById("graph");
    return { w: Math.max(1, box.clientWidth), h: Math.max(1, box.clientHeight) };
  }

  // Fit: the whole view inside the panel, centred, never magnified past FIT_MAX.
  function fit() {
    const b = view.extent, p = panelSize();
    view.cam = { x: b.x + b.w / 2, y: b.y + b.h / 2, k: Math.min(p.w / b.w, p.h / b.h, FIT_MAX) };
    view.fitK = view.cam.k;
    view.moved = false;
  }

  // The viewBox from the camera, with the panel's aspect ratio (so 1 unit is k pixels both ways).
  function applyCamera() {
    if (!view.svg || !view.cam) return;
    const p = panelSize(), c = view.cam;
    const w = p.w / c.k, h = p.h / c.k;
    view.svg.setAttribute("viewBox", `${c.x - w / 2} ${c.y - h / 2} ${w} ${h}`);
    view.svg.dataset.scale = c.k.toFixed(4);
  }

  // Zoom by factor f about (ux, uy) in layout units (the panel's centre by default).
  function zoom(f, ux, uy) {
    const c = view.cam;
    if (!c) return;
    const k = Math.min(ZOOM_MAX, Math.max(Math.min(view.fitK, 0.1) / 2, c.k * f));
    f = k / c.k;
    if (ux === undefined) { ux = c.x; uy = c.y; }
    view.cam = { x: ux - (ux - c.x) / f, y: uy - (uy - c.y) / f, k };
    view.moved = true;
    applyCamera();
  }

  // A point of the panel (client pixels) in layout units.
  function toLayout(clientX, clientY) {
    const r = document.getElementById("graph").getBoundingClientRect(), c = view.cam;
    return { x: c.x + (clientX - r.left - r.width / 2) / c.k, y: c.y + (clientY - r.top - r.height / 2) / c.k };
  }

  function setupGraphControls() {
    const panel = document.getElementById("graph");
    panel.addEventListener("wheel", (ev) => {
      if (!view.cam) return;
      ev.preventDefault();
      const p = toLayout(ev.clientX, ev.clientY);
      zoom(Math.exp(-ev.deltaY * (ev.deltaMode === 1 ? 0.05 : 0.0015)), p.x, p.y);
    }, { passive: false });
    let drag = null;
    panel.addEventListener("pointerdown", (ev) => {
      if (ev.button !== 0 || !view.cam) return;
      drag = { id: ev.pointerId, x: ev.clientX, y: ev.clientY, cam: Object.assign({}, view.cam) };
      panel.setPointerCapture(ev.pointerId);
    });
    panel.addEventListener("pointermove", (ev) => {
      if (!drag || ev.pointerId !== drag.id) return;
      const dx = ev.clientX - drag.x, dy = ev.clientY - drag.y;
      if (!view.moved && Math.abs(dx) + Math.abs(dy) < 3) return;  // a click, not a drag
      panel.classList.add("dragging");
      view.cam = { x: drag.cam.x - dx / drag.cam.k, y: drag.cam.y - dy / drag.cam.k, k: drag.cam.k };
      view.moved = true;
      applyCamera();
    });
    const end = () => { drag = null; panel.classList.remove("dragging"); };
    panel.addEventListener("pointerup", end);
    panel.addEventListener("pointercancel", end);
    document.getElementById("zoom-in").addEventListener("click", () => zoom(1.5));
    document.getElementById("zoom-out").addEventListener("click", () => zoom(1 / 1.5));
    document.getElementById("fit").addEventListener("click", () => { view.found = null; fit(); renderGraph(); });
    for (const mode of ["frontier", "full"]) {
      document.getElementById(`view-${mode}`).addEventListener("click", () => {
        view.mode = mode; view.moved = false;
        history.replaceState(null, "", mode === "full" ? "#full" : location.pathname);
        renderGraph();
      });
    }
    const input = document.getElementById("find");
    document.getElementById("find-form").addEventListener("submit", (ev) => { ev.preventDefault(); find(input.value); });
    input.addEventListener("change", () => find(input.value));
    new ResizeObserver(() => { if (!view.svg) return; if (!view.moved) fit(); applyCamera(); }).observe(panel);
  }

  // Find a part by id (exact, then ignoring case, then a unique prefix): centre it, outlined; a part
  // off the frontier is shown in the full graph.
  function find(q) {
    const note = document.getElementById("find-note");
    q = q.trim();
    if (!view.graph.length) return;
    // Enter in the box both changes and submits it: find once
    if (q === view.lastFind && performance.now() - view.lastFindAt < 300) return;
    view.lastFind = q; view.lastFindAt = performance.now();
    if (!q) { view.found = null; note.textContent = ""; renderGraph(); return; }
    const ids = view.graph[view.strategy].nodes.map((n) => n.id), lower = q.toLowerCase();
    let id = ids.find((i) => i === q) ?? ids.find((i) => i.toLowerCase() === lower);
    if (id === undefined) {
      const starts = ids.filter((i) => i.toLowerCase().startsWith(lower));
      if (starts.length !== 1) {
        note.textContent = starts.length ? `${starts.length} parts start with "${q}": type more of the id`
                                         : `no part "${q}" in this plan`;
        return;
      }
      id = starts[0];
    }
    view.found = id;
    if (!view.layout.nodes.some((n) => n.id === id)) {
      view.mode = "full";
      history.replaceState(null, "", "#full");
    }
    renderGraph();
    const n = view.layout.nodes.find((m) => m.id === id);
    view.cam = { x: n.x, y: n.y, k: Math.max(view.cam.k, 1) };
    view.moved = true;
    applyCamera();
    const g = view.svg.querySelector(`[data-part="${CSS.escape(id)}"]`);
    note.textContent = `${id}: ${g ? g.dataset.state : ""}`;
  }

  function renderGraph() {
    const select = document.getElementById("strategy");
    if (view.graph.length > 1) {
      const open = new Set(view.run.state.strategies);
      if (!view.chosen && !open.has(view.graph[view.strategy].strategy)) {  // follow the strategies still open
        const first = view.graph.findIndex((g) => open.has(g.strategy));
        if (first >= 0) view.strategy = first;
      }
      const labels = view.graph.map((g) => `strategy ${g.strategy}` + (open.has(g.strategy) ? "" : " (ruled out)"));
      if ([...select.options].map((o) => o.textContent).join("|") !== labels.join("|")) {
        select.replaceChildren(...labels.map((text, i) => el("option", { value: i, text })));
        select.value = String(view.strategy);
      }
      select.hidden = false;
      select.onchange = () => { view.strategy = Number(select.value); view.chosen = true; view.moved = false; renderGraph(); };
    }
    const g = view.graph[view.strategy];
    const s = nodeStates(view.run);
    const key = `${view.mode}/${view.strategy}`;
    let lay, note;
    if (view.mode === "frontier") {
      const f = frontier(g, s);
      lay = frontierLayout(g, f.shown);
      const hidden = g.nodes.length - f.shown.size;
      note = f.complete ? `Complete: the last ${f.shown.size} parts of the plan`
        : `Frontier: ${f.shown.size} of ${g.nodes.length.toLocaleString("en-US")} parts (installed boundary, ` +
          "installable now, visible, buffered, pending, next layer)" + (hidden ? `; ${hidden.toLocaleString("en-US")} not shown` : "");
    } else {
      lay = g;
      note = `Full graph: ${g.nodes.length.toLocaleString("en-US")} parts, ${g.edges.length.toLocaleString("en-US")} ` +
             "constraints (the minimal ones); drag to pan, wheel to zoom";
    }
    const svg = drawGraph(lay, s, view.mode === "frontier");
    svg.dataset.view = view.mode;
    document.getElementById("graph").replaceChildren(svg);
    view.svg = svg; view.layout = lay; view.extent = extent(lay);
    if (key !== view.drawn) {  // another view or strategy: its part ids for the search box, and a fresh fit
      if (view.drawn === undefined || view.drawn.split("/")[1] !== String(view.strategy)) {
        document.getElementById("part-ids").replaceChildren(...g.nodes.map((n) => el("option", { value: n.id })));
      }
      view.drawn = key;
      if (!view.found) view.moved = false;
    }
    if (!view.moved || !view.cam) fit();  // until the user moves the view, it follows the run
    applyCamera();
    document.getElementById("graph-note").textContent = note;
    for (const mode of ["frontier", "full"]) {
      document.getElementById(`view-${mode}`).setAttribute("aria-pressed", String(view.mode === mode));
    }
  }

  function renderCount() {
    const run = view.run;
    const count = document.getElementById("count");
    count.textContent = countText(run.count);
    count.dataset.value = run.count ? run.count.value : "";
    count.classList.toggle("long", count.textContent.length > 11);  // 15 grouped digits still fit the card
    document.getElementById("progress").textContent =
      `${run.progress.installed.toLocaleString("en-US")} of ${run.progress.units.toLocaleString("en-US")} installed` +
      ` · buffer ${run.state.buffered.length}` +
      (run.buffer_capacity === null ? " (unlimited)" : ` of ${run.buffer_capacity}`) +
      (run.state.defects ? ` · ${run.state.defects} defective` : "") +
      (view.graph.length > 1 ? ` · strategies still open: ${run.state.strategies.join(", ") || "none"}` : "");
    renderChart();
  }

  // The sequences left against the units installed, on a log scale relative to the start: log10 of the
  // count over log10 of the first count, from 1 (the start, top) to 0 (one sequence left, the end). The
  // x axis spans the whole plan, so the line moves down and right as units go in, at any plan size;
  // a dashed line shows the way to the end. One point per number of units installed (buffer moves and
  // shakes leave the count as it is). O(rows).
  function renderChart() {
    const run = view.run, box = document.getElementById("chart");
    const byInstalled = new Map();
    for (const r of view.rows) if (r.count) byInstalled.set(r.installed.length, r.count);
    if (run.count) byInstalled.set(run.progress.installed, run.count);
    const known = [...byInstalled.entries()].sort((p, q) => p[0] - q[0]);
    const W = Math.max(200, Math.round(box.clientWidth || 300)), H = 150, L = 8, R = 10, T = 22, B = 20;
    const units = Math.max(1, run.progress.units);
    const svg = el("svg:svg", { viewBox: `0 0 ${W} ${H}`, width: W, height: H, role: "img",
                                "aria-label": "admissible sequences left per unit installed, log scale" });
    box.replaceChildren(svg);
    if (!known.length) return;
    const c0 = known[0][1];
    const top = c0.log10 || 0;  // log10 of the first count known (null: a count of 0)
    const x = (v) => L + (W - L - R) * v / units;
    const y = (c) => (H - B) - (H - B - T) * (top > 0 ? Math.max(0, c.log10 || 0) / top : 0);
    const pts = known.map(([n, c]) => [x(n), y(c)]);
    const [lx, ly] = pts[pts.length - 1];
    svg.dataset.series = JSON.stringify(known.map(([n, c]) => [n, top > 0 ? (c.log10 || 0) / top : 0]));
    svg.append(el("svg:line", { class: "axis", x1: L, y1: H - B, x2: W - R, y2: H - B }),
               el("svg:line", { class: "axis", x1: L, y1: T, x2: L, y2: H - B }),
               el("svg:text", { x: L + 4, y: T - 8, class: "top-label", text: countText(c0) }),
               el("svg:text", { x: W - R, y: H - 6, "text-anchor": "end", text: `${units.toLocaleString("en-US")} installed: 1 left` }),
               el("svg:text", { x: L, y: H - 6, text: "units installed →" }));
    if (lx < W - R - 1) svg.append(el("svg:line", { class: "to-come", x1: lx, y1: ly, x2: x(units), y2: H - B }));
    svg.append(el("svg:polyline", { class: "line", points: pts.map((p) => p.join(",")).join(" ") }));
    for (const [px, py] of pts) svg.append(el("svg:circle", { class: "dot", cx: px, cy: py, r: 2.5 }));
    svg.append(el("svg:circle", { class: "now", cx: lx, cy: ly, r: 4 }));
  }

  // What a complete run took (run.totals, from the service), with its sequence and policy.
  function renderSummary() {
    const run = view.run, t = run.totals, card = document.getElementById("summary");
    card.hidden = !t;
    if (!t) return;
    const took = (new Date(run.updated_at) - new Date(run.created_at)) / 1000;
    const duration = took < 90 ? `${took.toFixed(0)} s` : took < 5400 ? `${(took / 60).toFixed(1)} min` : `${(took / 3600).toFixed(1)} h`;
    const n = (v) => v.toLocaleString("en-US");
    const tiles = [
      ["parts installed", `${n(t.installed)} of ${n(run.progress.units)}`],
      ["looks", n(t.looks)],
      ["motions", n(t.motions)],
      ["buffer moves", `${n(t.buffer_moves)} (peak ${n(t.buffer_peak)}${run.buffer_capacity === null ? "" : ` of ${run.buffer_capacity}`})`],
      ["shakes", n(t.shakes)],
      ["time (motions, shakes, looks)", Number(t.time.toFixed(2)).toLocaleString("en-US")],
      ["failed · defective", `${n(t.failed)} · ${n(t.defects)}`],
      ["policy", run.policy],
      ["took", duration],
    ];
    document.getElementById("summary-tiles").replaceChildren(...tiles.map(([k, v]) =>
      el("div", { class: "tile", "data-total": k }, el("span", { class: "k", text: k }), el("span", { class: "v", text: v }))));
    document.getElementById("sequence").replaceChildren(...run.state.installed.map((p) => el("li", { text: p })));
  }

  function renderPending() {
    const run = view.run;
    const p = run.pending;
    document.getElementById("pending").textContent =
      p ? `${p.action_text} — waiting for the outcome` : (run.status === "complete" ? "done: the assembly is complete" : "none: waiting for a look");
    document.getElementById("explain").textContent = p ? p.reasons.explain : "";
  }

  // as Decision.certainty writes it: an estimate is never certain, so past 99.9% it says so
  const sure = (c) => (c < 0.9995 ? `${(100 * c).toFixed(1)}%` : "over 99.9%");

  function renderTrace(fresh) {
    const tbody = document.querySelector("#trace tbody");
    const old = tbody.children.length;
    const rows = view.rows.map((r, i) => el("tr", { class: (r.outcome === null && r.action.kind !== "done" ? "pending-row" : "") +
                                                       (fresh && i >= old - 1 ? " fresh" : ""), "data-n": r.n },
      el("td", { text: r.n }),
      el("td", { text: fmtList(r.visible) }),
      el("td", { text: fmtList(r.buffered) }),
      el("td", { text: fmtList(r.installed) }),
      // An estimated decision (exact counts did not fit the decision budget) is marked with the one thing
      // it states (its explanation's last line): a near tie, or how sure it is of the exact rule's choice.
      el("td", { text: r.action_text + (r.reasons && r.reasons.exact === false && r.reasons.method !== "replayed"
                   ? ` (≈ ${r.reasons.close ? "near tie" : `${sure(r.reasons.confidence)} sure`})` : ""),
                 title: r.reasons ? r.reasons.explain : "" }),
      el("td", { text: r.outcome === null ? (r.action.kind === "done" ? "" : "pending") : r.outcome })));
    tbody.replaceChildren(...rows);
  }
}

document.addEventListener("DOMContentLoaded", () => {
  const page = document.body.dataset.page;
  if (page === "index") initIndex();
  if (page === "run") initRun();
});
