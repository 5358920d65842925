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

const fmtList = (xs) => (xs || []).join(",");

function fmtCount(c) {
  if (!c) return "—";
  const v = c.value;
  if (v.length <= 15) return Number(v).toLocaleString("en-US");
  return `${v[0]}.${v.slice(1, 4)}e${v.length - 1}`;
}

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
          el("td", { text: r.count === null ? "—" : fmtCount({ value: r.count }) }),
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
  const view = { run: null, rows: [], graph: [], strategy: 0, chosen: false, es: null, seq: -1, retry: null };
  const relogin = setupLogin(connect);

  function setLive(on, text) {
    const live = document.getElementById("live");
    live.className = "live " + (on ? "on" : "off");
    live.textContent = text;
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
    renderGraph();
    renderCount();
    renderPending();
    renderTrace(fresh);
  }

  function nodeStates(run) {
    const installed = {}, buffered = new Set(run.state.buffered), visible = new Set(run.last_look);
    for (const p of run.state.installed) installed[p] = (installed[p] || 0) + 1;
    const pendingPart = run.pending && run.pending.action.part;
    return { installed, buffered, visible, installable: new Set(run.installable), pendingPart };
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
      select.onchange = () => { view.strategy = Number(select.value); view.chosen = true; renderGraph(); };
    }
    const g = view.graph[view.strategy];
    const s = nodeStates(view.run);
    const svg = el("svg:svg", { width: g.width, height: g.height, viewBox: `0 0 ${g.width} ${g.height}`, role: "img",
                                "aria-label": "precedence graph" });
    svg.append(el("svg:defs", {}, el("svg:marker", { id: "arrow", viewBox: "0 0 10 10", refX: 10, refY: 5,
      markerWidth: 7, markerHeight: 7, orient: "auto-start-reverse" }, el("svg:path", { d: "M 0 0 L 10 5 L 0 10 z", fill: "#9aa3ad" }))));
    const W = 44, H = 26;
    const quantity = Object.fromEntries(g.nodes.map((n) => [n.id, n.quantity]));
    for (const e of g.edges) {
      const pts = e.points.map((p) => p.slice());
      pts[0][0] += W / 2; pts[pts.length - 1][0] -= W / 2;
      const done = (s.installed[e.from] || 0) >= quantity[e.from];
      svg.append(el("svg:polyline", { class: "edge" + (done ? " done" : ""), points: pts.map((p) => p.join(",")).join(" "),
                                      "marker-end": "url(#arrow)", "data-edge": `${e.from}>${e.to}` }));
    }
    for (const n of g.nodes) {
      const k = s.installed[n.id] || 0;
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
      const title = (n.name ? `${n.id} (${n.name})` : n.id) + (n.quantity > 1 ? `: ${k} of ${n.quantity} installed` : `: ${state}`);
      const grp = el("svg:g", { class: cls.join(" "), "data-part": n.id, "data-state": state },
        el("svg:title", { text: title }),
        el("svg:rect", { x: n.x - W / 2, y: n.y - H / 2, width: W, height: H, rx: 6 }),
        el("svg:text", { x: n.x, y: n.y - (n.quantity > 1 ? 4 : 0), text: n.id }));
      if (n.quantity > 1) grp.append(el("svg:text", { class: "units", x: n.x, y: n.y + 8, text: `${k}/${n.quantity}` }));
      svg.append(grp);
    }
    document.getElementById("graph").replaceChildren(svg);
  }

  function renderCount() {
    const run = view.run;
    document.getElementById("count").textContent = fmtCount(run.count);
    document.getElementById("count").dataset.value = run.count ? run.count.value : "";
    document.getElementById("progress").textContent =
      `${run.progress.installed} of ${run.progress.units} installed · buffer ${run.state.buffered.length}` +
      (run.buffer_capacity === null ? " (unlimited)" : ` of ${run.buffer_capacity}`) +
      (run.state.defects ? ` · ${run.state.defects} defective` : "") +
      (view.graph.length > 1 ? ` · strategies still open: ${run.state.strategies.join(", ") || "none"}` : "");
    // The count before each row, then now: it falls as the run proceeds.
    const pts = view.rows.filter((r) => r.count).map((r) => [r.n, r.count.log10]);
    if (run.count && !run.pending) pts.push([view.rows.length + 1, run.count.log10]);
    const W = 320, H = 150, L = 34, B = 18;
    const svg = el("svg:svg", { viewBox: `0 0 ${W} ${H}`, preserveAspectRatio: "none", "aria-label": "sequences left per step" });
    const maxX = Math.max(2, ...pts.map((p) => p[0]));
    const maxY = Math.max(0.3, ...pts.map((p) => p[1] === null ? 0 : p[1]));
    const x = (v) => L + (W - L - 6) * (v - 1) / (maxX - 1);
    const y = (v) => (H - B) - (H - B - 8) * ((v === null ? 0 : v) / maxY);
    svg.append(el("svg:line", { class: "axis", x1: L, y1: H - B, x2: W, y2: H - B }),
               el("svg:line", { class: "axis", x1: L, y1: 4, x2: L, y2: H - B }),
               el("svg:text", { x: 2, y: 12, text: fmtCount({ value: String(Math.round(10 ** maxY)) }) }),
               el("svg:text", { x: 2, y: H - B, text: "1" }),
               el("svg:text", { x: L, y: H - 4, text: "step 1" }),
               el("svg:text", { x: W - 40, y: H - 4, text: `step ${maxX}` }),
               el("svg:text", { x: W - 60, y: 12, text: "log scale" }));
    if (pts.length) {
      svg.append(el("svg:polyline", { class: "line", points: pts.map((p) => `${x(p[0])},${y(p[1])}`).join(" ") }));
      for (const p of pts) svg.append(el("svg:circle", { class: "dot", cx: x(p[0]), cy: y(p[1]), r: 2.5 }));
    }
    document.getElementById("chart").replaceChildren(svg);
  }

  function renderPending() {
    const run = view.run;
    const p = run.pending;
    document.getElementById("pending").textContent =
      p ? `${p.action_text} — waiting for the outcome` : (run.status === "complete" ? "done: the assembly is complete" : "none: waiting for a look");
    document.getElementById("explain").textContent = p ? p.reasons.explain : "";
  }

  function renderTrace(fresh) {
    const tbody = document.querySelector("#trace tbody");
    const old = tbody.children.length;
    const rows = view.rows.map((r, i) => el("tr", { class: (r.outcome === null && r.action.kind !== "done" ? "pending-row" : "") +
                                                       (fresh && i >= old - 1 ? " fresh" : ""), "data-n": r.n },
      el("td", { text: r.n }),
      el("td", { text: fmtList(r.visible) }),
      el("td", { text: fmtList(r.buffered) }),
      el("td", { text: fmtList(r.installed) }),
      // An estimated decision (exact counts did not fit the decision budget) is marked, with how sure it is.
      el("td", { text: r.action_text + (r.reasons && r.reasons.exact === false && r.reasons.method !== "replayed"
                   ? ` (≈ ${(100 * r.reasons.confidence).toFixed(0)}% sure)` : ""),
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
