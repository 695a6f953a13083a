// The hli-server dashboard (docs/dashboard.md): one script, no build step, no library.
//
// It draws the machine as it was when the page was served (the data block #initial: hello, state,
// scenes and the newest events, put in by the server) before the page's load event, then listens to the
// server's event stream /api/live (hello once, state at 20 Hz, every typed event, a channel's scene
// when it changed) and acts through the control API (docs/api.md). The pictures are
// the scenes the server computes with hli_server/scene.py, the same function `check --plot` draws:
// this script only draws them (SVG). Between two scenes it moves the TCP and draws its newest trail
// from the 20 Hz states.
//
// With --api-token the server refuses state changes without `Authorization: Bearer <token>`: the page
// asks for the token once (kept in this tab's sessionStorage) and sends it with every POST. The events
// (the event log, live) come on the stream only with the token: an EventSource sends no headers, so the
// page puts it on the stream's URL (`?access_token=`, RFC 6750) and reconnects once it has it.
"use strict";

const SVG = "http://www.w3.org/2000/svg";
const COLOURS = { WORK: "#2e8b57", PROT: "#c0392b", path: "#1f4e9c", refused: "#e31a1c", stop: "#d35400",
  ahead: "#7f8c8d", tcp: "#111111" };
const VIRIDIS = ["#440154", "#3b528b", "#21918c", "#5ec962", "#fde725"];
const RELATION_TEXT = {
  crosses: "path goes through it", "crosses WORK": "path in it", above: "path passes above",
  below: "path passes below", above_and_below: "path passes above and below", apart: "path never over it",
};
const TOP = { width: 560, height: 420, pad: 34 };
const SIDE = { width: 560, height: 170, pad: 34 };
const TAIL_POINTS = 2000;
const EVENTS_SHOWN = 200;
const HISTORY_SHOWN = 200;

const state = {
  hello: null,
  channels: new Map(), // number -> {el, scene, tail, ...}
  axisRows: new Map(),
  token: sessionStorage.getItem("hli-token") || "",
  source: null,
  pending: null,
  lastAlarms: "",
  lastPairs: "",
  lastExternal: "",
};
const EXTERNAL_ELEMENTS_SHOWN = 32;
const MESSAGES_SHOWN = 200;

// --- small helpers -----------------------------------------------------------------------------
function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === null || v === undefined || v === false) continue;
    if (k === "text") node.textContent = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else node.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children) node.append(c);
  return node;
}

function svg(tag, attrs = {}, parent = null) {
  const node = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v !== null && v !== undefined) node.setAttribute(k, v);
  }
  if (parent) parent.append(node);
  return node;
}

function num(v, digits = 3) {
  if (v === null || v === undefined || Number.isNaN(v)) return "-";
  const text = Number(v).toFixed(digits);
  return text === "-0." + "0".repeat(digits) ? (0).toFixed(digits) : text;
}

function say(text, kind = "info") {
  const m = document.getElementById("message");
  m.textContent = text;
  m.className = "message " + kind;
}

function setText(node, text) {
  if (node.textContent !== text) node.textContent = text;
}

function viridis(f) {
  const x = Math.min(Math.max(f, 0), 1) * (VIRIDIS.length - 1);
  const k = Math.min(Math.floor(x), VIRIDIS.length - 2);
  const t = x - k;
  const a = VIRIDIS[k], b = VIRIDIS[k + 1];
  const mix = (i) => Math.round(parseInt(a.slice(i, i + 2), 16) * (1 - t) + parseInt(b.slice(i, i + 2), 16) * t);
  return `rgb(${mix(1)},${mix(3)},${mix(5)})`;
}

// is b on the straight line from a on to c (within 0.01 mm, in the base plane and the height)?
function onLine(a, b, c) {
  const d = [c[0] - a[0], c[1] - a[1], (c[2] || 0) - (a[2] || 0)];
  const e = [b[0] - a[0], b[1] - a[1], (b[2] || 0) - (a[2] || 0)];
  const dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  if (dd === 0) return false;
  const t = (d[0] * e[0] + d[1] * e[1] + d[2] * e[2]) / dd;
  if (t < 0 || t > 1) return false;
  const off = [e[0] - t * d[0], e[1] - t * d[1], e[2] - t * d[2]];
  return off[0] * off[0] + off[1] * off[1] + off[2] * off[2] < 1e-4;
}

function niceStep(span, count) {
  const raw = span / Math.max(count, 1);
  const p = Math.pow(10, Math.floor(Math.log10(raw)));
  for (const m of [1, 2, 5, 10]) if (m * p >= raw) return m * p;
  return 10 * p;
}

// --- the control API ---------------------------------------------------------------------------
async function api(method, path, body, what) {
  const headers = {};
  if (body !== undefined) headers["content-type"] = "application/json";
  if (state.token) headers["authorization"] = "Bearer " + state.token;
  let answer;
  try {
    answer = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  } catch (err) {
    say(`${what}: the server does not answer (${err})`, "error");
    return null;
  }
  let data = null;
  try { data = await answer.json(); } catch (_) { data = null; }
  if (answer.status === 401) {
    state.pending = () => api(method, path, body, what);
    askToken(state.token ? "the token was refused; enter the server's API token" : null);
    return null;
  }
  if (!answer.ok) {
    const detail = data && data.detail !== undefined ? data.detail : answer.statusText;
    say(`${what}: refused (${answer.status}): ${typeof detail === "string" ? detail : JSON.stringify(detail)}`, "error");
    return null;
  }
  if (data && data.effective_cycle !== undefined) say(`${what}: accepted, latched in cycle ${data.effective_cycle}`);
  else say(`${what}: done`);
  return data;
}

function askToken(reason) {
  const form = document.getElementById("token-form");
  form.hidden = false;
  if (reason) say(reason, "error");
  document.getElementById("token").focus();
}

function setUpToken() {
  const form = document.getElementById("token-form");
  form.addEventListener("submit", (ev) => {
    ev.preventDefault();
    state.token = document.getElementById("token").value.trim();
    sessionStorage.setItem("hli-token", state.token);
    form.hidden = true;
    if (state.hello && state.hello.events === false) connect();  // again, with the events
    const retry = state.pending;
    state.pending = null;
    if (retry) retry();
    else say("token kept for this tab");
  });
}

// --- the channel cards -------------------------------------------------------------------------
function channelCard(ch) {
  const n = ch.number;
  const id = (s) => `ch${n}-${s}`;
  const post = (path, body, what) => api("POST", `/api/channels/${n}/${path}`, body, `channel ${n}: ${what}`);

  const programSelect = el("select", { id: id("program"), "aria-label": "program of the table" });
  for (const p of ch.programs) programSelect.append(el("option", { value: p.number, text: `${p.number} ${p.name}` }));
  const text = el("textarea", { id: id("text"), rows: 6, spellcheck: "false",
    placeholder: "N10 G01 X100 Y0 F3000\nN20 M30" });
  const override = el("input", { id: id("override"), type: "range", min: 0, max: 120, step: 1, value: 100,
    "aria-label": "feed override %" });
  const overrideText = el("output", { id: id("override-value"), text: "100 %" });
  // the slider shows the override in effect (showOverride), except while the operator moves it and until
  // the server took what was set (or refused it)
  override.addEventListener("input", () => { override.dataset.touched = "1"; overrideText.textContent = `${override.value} %`; });
  override.addEventListener("change", async () => {
    override.dataset.touched = "1";
    const percent = Number(override.value);
    const answer = await post("override", { percent }, `override ${override.value} %`);
    if (answer && answer.effective_cycle !== undefined) override.dataset.until = String(answer.effective_cycle);
    delete override.dataset.touched;
  });

  const jogs = el("div", { class: "jog" });
  for (const axis of ch.axes) {
    for (const [dir, label] of [[-1, "−"], [1, "+"]]) {
      const b = el("button", { type: "button", id: id(`jog-${axis}${dir > 0 ? "plus" : "minus"}`), text: `${axis}${label}`,
        title: "hold to jog (manual mode)" });
      const release = () => { if (b.dataset.down) { delete b.dataset.down; post("jog", { axis, direction: 0 }, `jog ${axis} released`); } };
      b.addEventListener("pointerdown", () => { b.dataset.down = "1"; post("jog", { axis, direction: dir }, `jog ${axis}${label}`); });
      b.addEventListener("pointerup", release);
      b.addEventListener("pointerleave", release);
      jogs.append(b);
    }
  }

  // each view is two SVGs on top of each other: the scene (redrawn when a scene comes) and the live layer
  // (TCP, newest trail, path ahead: 20 times a second), so that the browser repaints only the small one
  const topLive = svg("svg", { id: id("top-live"), class: "live", viewBox: `0 0 ${TOP.width} ${TOP.height}`, "aria-hidden": "true" });
  const sideLive = svg("svg", { id: id("side-live"), class: "live", viewBox: `0 0 ${SIDE.width} ${SIDE.height}`, "aria-hidden": "true" });
  const top = svg("svg", { id: id("top"), class: "top", viewBox: `0 0 ${TOP.width} ${TOP.height}`, role: "img",
    "aria-label": `channel ${n}: base plane with areas, path and TCP` });
  const side = svg("svg", { id: id("side"), class: "side", viewBox: `0 0 ${SIDE.width} ${SIDE.height}`, role: "img",
    "aria-label": `channel ${n}: height along the path with the areas' height bands` });
  const legend = el("ul", { id: id("legend"), class: "legend" });

  const card = el("article", { class: "channel panel", id: id("card") },
    el("h2", { text: `Channel ${n}` }),
    el("dl", { class: "status" },
      el("dt", { text: "mode" }), el("dd", { id: id("mode"), text: "-" }),
      el("dt", { text: "program state" }), el("dd", {}, el("span", { id: id("state"), class: "badge", text: "-" })),
      el("dt", { text: "program" }), el("dd", { id: id("progname"), text: "-" }),
      el("dt", { text: "active block" }), el("dd", { id: id("block"), text: "-" }),
      el("dt", { text: "holds" }), el("dd", { id: id("holds"), text: "-" }),
      el("dt", { text: "override" }), el("dd", { id: id("override-state"), text: "-" }),
      el("dt", { text: "kinematics" }), el("dd", { id: id("kinematic"), text: "-" }),
      el("dt", { text: "tool tip (TCP)" }), el("dd", { id: id("tcp"), text: "-" }),
    ),
    el("div", { class: "controls" },
      el("span", { class: "group" }, programSelect,
        el("button", { type: "button", id: id("select"), text: "Select",
          onclick: () => api("POST", `/api/channels/${n}/select`, { number: Number(programSelect.value) }, `channel ${n}: select program ${programSelect.value}`) })),
      el("span", { class: "group" },
        el("button", { type: "button", id: id("start"), class: "go", text: "Start", onclick: () => post("start", undefined, "start") }),
        el("button", { type: "button", id: id("feedhold"), text: "Feedhold", onclick: () => {
          const on = !state.channels.get(n).feedhold;
          post("feedhold", { on }, `feedhold ${on ? "on" : "off"}`);
        } }),
        el("button", { type: "button", id: id("reset"), class: "stop", text: "Reset", onclick: () => post("reset", undefined, "reset") })),
      el("span", { class: "group" },
        el("button", { type: "button", id: id("auto"), text: "Automatic", onclick: () => post("mode", { mode: "automatic" }, "mode automatic") }),
        el("button", { type: "button", id: id("manual"), text: "Manual", onclick: () => post("mode", { mode: "manual" }, "mode manual") })),
      el("label", { class: "group" }, "override ", override, overrideText),
    ),
    el("div", { class: "controls" }, el("span", { class: "label", text: "jog" }), jogs),
    el("details", { class: "load" },
      el("summary", { text: "load an NC program" }), text,
      el("button", { type: "button", id: id("load"), text: "Load",
        onclick: () => api("POST", `/api/channels/${n}/program`, { text: text.value, name: "dashboard" }, `channel ${n}: load program`) })),
    el("figure", {}, el("div", { class: "view" }, top, topLive), el("div", { class: "view", id: id("side-view") }, side, sideLive),
      el("figcaption", {}, legend)),
  );
  return { number: n, card, top, side, topLive, sideLive, legend, scene: null, tail: [], tailS: 0, feedhold: false, tcp: null };
}

// --- drawing a scene ---------------------------------------------------------------------------
function viewBounds(scene, extra) {
  let [a0, a1] = scene.bounds.a, [b0, b1] = scene.bounds.b;
  for (const p of extra) {
    a0 = Math.min(a0, p[0]); a1 = Math.max(a1, p[0]);
    b0 = Math.min(b0, p[1]); b1 = Math.max(b1, p[1]);
  }
  const span = Math.max(a1 - a0, b1 - b0, 20);
  const grow = span * 0.08;
  const ca = (a0 + a1) / 2, cb = (b0 + b1) / 2;
  const ha = Math.max(a1 - a0, 20) / 2 + grow, hb = Math.max(b1 - b0, 20) / 2 + grow;
  return [ca - ha, ca + ha, cb - hb, cb + hb];
}

function topMapper([a0, a1, b0, b1]) {
  const w = TOP.width - 2 * TOP.pad, h = TOP.height - 2 * TOP.pad;
  const k = Math.min(w / (a1 - a0), h / (b1 - b0)); // one scale for both axes: circles stay round
  const ox = TOP.pad + (w - k * (a1 - a0)) / 2, oy = TOP.pad + (h - k * (b1 - b0)) / 2;
  return { k, a0, a1, b0, b1, x: (a) => ox + (a - a0) * k, y: (b) => oy + (b1 - b) * k };
}

function sideMapper(s0, s1, h0, h1) {
  if (s1 - s0 < 1e-6) s1 = s0 + 1;
  if (h1 - h0 < 1e-6) { h0 -= 10; h1 += 10; }
  const gh = (h1 - h0) * 0.1; h0 -= gh; h1 += gh;
  const w = SIDE.width - 2 * SIDE.pad, h = SIDE.height - 2 * SIDE.pad;
  return { s0, s1, h0, h1, x: (s) => SIDE.pad + (s - s0) / (s1 - s0) * w, y: (v) => SIDE.pad + (h1 - v) / (h1 - h0) * h };
}

function grid(g, xs, ys, m, width, height, pad, xLabel, yLabel) {
  const [x0, x1] = xs, [y0, y1] = ys;
  const stepX = niceStep(x1 - x0, 6), stepY = niceStep(y1 - y0, 5);
  for (let v = Math.ceil(x0 / stepX) * stepX; v <= x1; v += stepX) {
    const x = m.x(v);
    svg("line", { x1: x, x2: x, y1: pad, y2: height - pad, class: "grid" }, g);
    svg("text", { x, y: height - pad + 14, class: "tick", "text-anchor": "middle" }, g).textContent = +v.toFixed(6);
  }
  for (let v = Math.ceil(y0 / stepY) * stepY; v <= y1; v += stepY) {
    const y = m.y(v);
    svg("line", { x1: pad, x2: width - pad, y1: y, y2: y, class: "grid" }, g);
    svg("text", { x: pad - 4, y: y + 4, class: "tick", "text-anchor": "end" }, g).textContent = +v.toFixed(6);
  }
  svg("text", { x: width - pad, y: height - 4, class: "axis-label", "text-anchor": "end" }, g).textContent = xLabel;
  svg("text", { x: 4, y: pad - 8, class: "axis-label" }, g).textContent = yLabel;
}

function areaStyle(area) {
  const colour = COLOURS[area.kind] || COLOURS.WORK;
  const active = area.state === "active";
  const prot = area.kind === "PROT";
  const rel = area.relation || "apart";
  const style = { stroke: colour, "stroke-dasharray": active ? null : "6 4", "stroke-width": 1.2 };
  if (rel === "crosses") Object.assign(style, { fill: prot ? "url(#hatch-prot)" : colour, "fill-opacity": active ? 0.4 : 0.2, "stroke-width": 2.5 });
  else if (rel === "apart") Object.assign(style, { fill: prot ? "url(#hatch-prot)" : colour, "fill-opacity": active ? 0.18 : 0.08 });
  else Object.assign(style, { fill: prot ? "url(#dots-prot)" : "url(#dots-work)", "fill-opacity": 0.6 });
  return style;
}

function defs(root) {
  const d = svg("defs", {}, root);
  const hatch = svg("pattern", { id: "hatch-prot", width: 8, height: 8, patternUnits: "userSpaceOnUse",
    patternTransform: "rotate(45)" }, d);
  svg("rect", { width: 8, height: 8, fill: COLOURS.PROT, "fill-opacity": 0.35 }, hatch);
  svg("line", { x1: 0, y1: 0, x2: 0, y2: 8, stroke: COLOURS.PROT, "stroke-width": 2 }, hatch);
  for (const [name, colour] of [["dots-prot", COLOURS.PROT], ["dots-work", COLOURS.WORK]]) {
    const dots = svg("pattern", { id: name, width: 7, height: 7, patternUnits: "userSpaceOnUse" }, d);
    svg("circle", { cx: 3.5, cy: 3.5, r: 1.1, fill: colour }, dots);
  }
}

function star(g, x, y, r, attrs) {
  const pts = [];
  for (let k = 0; k < 10; k++) {
    const rad = k % 2 ? r * 0.45 : r, ang = -Math.PI / 2 + k * Math.PI / 5;
    pts.push(`${x + rad * Math.cos(ang)},${y + rad * Math.sin(ang)}`);
  }
  return svg("polygon", { points: pts.join(" "), ...attrs }, g);
}

function polyline(g, pts, attrs) {
  return svg("polyline", { points: pts.map((p) => `${p[0].toFixed(2)},${p[1].toFixed(2)}`).join(" "), fill: "none", ...attrs }, g);
}

function drawScene(c) {
  const scene = c.scene;
  const extra = c.tcp ? [c.tcp] : [];
  const m = topMapper(viewBounds(scene, extra));
  c.top.replaceChildren();
  c.legend.replaceChildren();
  defs(c.top);
  const view = scene.view;
  grid(svg("g", {}, c.top), [m.a0, m.a1], [m.b0, m.b1], m, TOP.width, TOP.height, TOP.pad, `${view.a} [mm]`, `${view.b} [mm]`);
  const areas = svg("g", { class: "areas" }, c.top);
  for (const area of scene.areas) {
    const band = `${area.height_axis} ${area.min}..${area.max}`;
    // the scene says what happened (hli_server/scene.py, relation_text); the table is for older scenes
    const how = area.relation_text || RELATION_TEXT[`${area.relation} ${area.kind}`] || RELATION_TEXT[area.relation] || area.relation;
    const label = `ID${area.id} ${area.kind} ${area.state}, ${band}: ${how}`;
    const li = el("li", { class: `area ${area.kind} ${area.state}`, "data-area": area.id, "data-relation": area.relation, text: label });
    if (!area.in_view) li.append(` (plane ${area.axes.join("/")}, not drawn)`);
    c.legend.append(li);
    if (!area.in_view) continue;
    const style = { ...areaStyle(area), "data-area": area.id, "data-kind": area.kind, "data-state": area.state,
      "data-relation": area.relation, class: `area ${area.kind}` };
    let shape;
    if (area.shape === "CIRC") {
      shape = svg("circle", { cx: m.x(area.center[0]), cy: m.y(area.center[1]), r: area.radius * m.k, ...style }, areas);
    } else {
      shape = svg("polygon", { points: area.points.map((p) => `${m.x(p[0])},${m.y(p[1])}`).join(" "), ...style }, areas);
    }
    svg("title", {}, shape).textContent = label;
    const anchor = area.shape === "CIRC" ? area.center : area.points[0];
    svg("text", { x: m.x(anchor[0]) + 4, y: m.y(anchor[1]) - 4, class: "area-label", fill: COLOURS[area.kind] }, areas).textContent =
      `ID${area.id} ${area.state === "active" ? "" : "(" + area.state + ") "}${band}`;
  }
  // the travelled path, coloured by height when the height changes
  const paths = svg("g", { class: "path" }, c.top);
  const heights = scene.path.flat().map((p) => p[2]).filter((h) => h !== null);
  const hMin = Math.min(...heights), hMax = Math.max(...heights);
  const coloured = heights.length > 1 && hMax - hMin > 1e-9;
  for (const line of scene.path) {
    if (coloured) {
      for (let k = 0; k + 1 < line.length; k++) {
        const f = ((line[k][2] + line[k + 1][2]) / 2 - hMin) / (hMax - hMin);
        svg("line", { x1: m.x(line[k][0]), y1: m.y(line[k][1]), x2: m.x(line[k + 1][0]), y2: m.y(line[k + 1][1]),
          stroke: viridis(f), "stroke-width": 2 }, paths);
      }
    } else {
      polyline(paths, line.map((p) => [m.x(p[0]), m.y(p[1])]), { stroke: COLOURS.path, "stroke-width": 2, id: `ch${c.number}-trail` });
    }
    if (line.length) svg("circle", { cx: m.x(line[0][0]), cy: m.y(line[0][1]), r: 3, fill: COLOURS.path }, paths);
  }
  c.legend.append(el("li", { class: "path", text: coloured ? `path: coloured by height ${view.height} ${num(hMin, 1)} (violet) .. ${num(hMax, 1)} (yellow)` : "path (blue), path ahead (grey, dashed)" }));
  if (scene.refused) {
    const r = scene.refused;
    polyline(paths, r.points.map((p) => [m.x(p[0]), m.y(p[1])]), { stroke: COLOURS.refused, "stroke-width": 2.5,
      "stroke-dasharray": "7 4", id: `ch${c.number}-refused` });
    c.legend.append(el("li", { class: "refused", text: `refused block ${r.block} (line ${r.line}, alarm ${r.alarm}, ${r.cause || `area ${r.area}`})` }));
  }
  if (scene.violation && scene.violation.point) {
    const v = scene.violation;
    star(paths, m.x(v.point[0]), m.y(v.point[1]), 10, { fill: COLOURS.refused, stroke: "#000", id: `ch${c.number}-violation` });
    const where = Object.entries(v.position).map(([k, x]) => `${k}${num(x, 4)}`).join(" ");
    c.legend.append(el("li", { class: "violation", text: `violation at ${where}, ${v.cause || `area ${v.area}`} (alarm ${v.alarm})` }));
  }
  if (scene.stop) {
    const s = scene.stop;
    svg("text", { x: m.x(s[0]), y: m.y(s[1]) + 5, class: "stop-mark", "text-anchor": "middle", fill: COLOURS.stop }, paths).textContent = "✕";
  }
  // the path ahead, from where the TCP was: the live layer's trail covers what the TCP has passed since
  polyline(paths, (scene.ahead || []).map((p) => [m.x(p[0]), m.y(p[1])]), { stroke: COLOURS.ahead, "stroke-width": 1.5,
    "stroke-dasharray": "5 4", id: `ch${c.number}-ahead` });
  // the live layer: the newest trail and the TCP
  c.topLive.replaceChildren();
  c.live = svg("g", { class: "live" }, c.topLive);
  c.tailLine = polyline(c.live, [], { stroke: COLOURS.path, "stroke-width": 2, id: `ch${c.number}-tail` });
  c.tcpMark = svg("g", { id: `tcp-${c.number}`, class: "tcp" }, c.live);
  svg("circle", { r: 6, fill: "none", stroke: COLOURS.tcp, "stroke-width": 2 }, c.tcpMark);
  svg("line", { x1: -10, x2: 10, y1: 0, y2: 0, stroke: COLOURS.tcp }, c.tcpMark);
  svg("line", { x1: 0, x2: 0, y1: -10, y2: 10, stroke: COLOURS.tcp }, c.tcpMark);
  c.m = m;
  drawSide(c);
  drawLive(c);
}

function drawSide(c) {
  const scene = c.scene;
  c.side.replaceChildren();
  c.sideLive.replaceChildren();
  const view = scene.view;
  const holder = document.getElementById(`ch${c.number}-side-view`);
  if (view.height === null) {
    holder.hidden = true;
    c.sm = null;
    return;
  }
  holder.hidden = false;
  defs(c.side);
  const pts = [...scene.path.flat(), ...(scene.ahead || []), ...(scene.refused ? scene.refused.points : [])];
  if (scene.position) pts.push(scene.position);
  const hs = pts.map((p) => p[2]).filter((h) => h !== null);
  for (const a of scene.areas) if (a.band_in_view && a.spans.length) hs.push(a.min, a.max);
  const sEnd = Math.max(scene.bounds.s[1], ...pts.map((p) => p[3]));
  const sm = sideMapper(0, sEnd * 1.05 + 1, Math.min(...hs, 0), Math.max(...hs, 0));
  grid(svg("g", {}, c.side), [sm.s0, sm.s1], [sm.h0, sm.h1], sm, SIDE.width, SIDE.height, SIDE.pad,
    "path length in the base plane [mm]", `${view.height} [mm]`);
  const g = svg("g", {}, c.side);
  for (const a of scene.areas) {
    if (!a.band_in_view) continue;
    for (const span of a.spans) {
      const x0 = sm.x(span.from), x1 = sm.x(span.to), y0 = sm.y(a.max), y1 = sm.y(a.min);
      svg("rect", { x: x0, y: y0, width: Math.max(x1 - x0, 2), height: y1 - y0, class: `band ${a.kind}`,
        fill: a.kind === "PROT" ? "url(#hatch-prot)" : COLOURS.WORK, "fill-opacity": a.state === "active" ? 0.35 : 0.15,
        stroke: COLOURS[a.kind], "stroke-dasharray": a.state === "active" ? null : "5 3", "data-area": a.id }, g);
      svg("text", { x: x0 + 2, y: y0 - 3, class: "area-label", fill: COLOURS[a.kind] }, g).textContent = `ID${a.id}`;
    }
  }
  for (const line of scene.path) polyline(g, line.map((p) => [sm.x(p[3]), sm.y(p[2])]), { stroke: COLOURS.path, "stroke-width": 2 });
  if (scene.refused) {
    polyline(g, scene.refused.points.map((p) => [sm.x(p[3]), sm.y(p[2])]), { stroke: COLOURS.refused, "stroke-width": 2.5, "stroke-dasharray": "7 4" });
  }
  if (scene.violation && scene.violation.point && scene.violation.point[2] !== null) {
    const v = scene.violation.point;
    star(g, sm.x(v[3]), sm.y(v[2]), 8, { fill: COLOURS.refused, stroke: "#000" });
  }
  polyline(g, (scene.ahead || []).map((p) => [sm.x(p[3]), sm.y(p[2])]), { stroke: COLOURS.ahead, "stroke-width": 1.5,
    "stroke-dasharray": "5 4" });
  c.sideLiveG = svg("g", {}, c.sideLive);
  c.sideTcp = svg("circle", { r: 5, fill: "none", stroke: COLOURS.tcp, "stroke-width": 2, id: `tcp-side-${c.number}` }, c.sideLiveG);
  c.sm = sm;
}

// the TCP and the trail since the scene, at the state's rate
function drawLive(c) {
  if (!c.m || !c.tcp) return;
  const m = c.m;
  const outside = c.tcp[0] < m.a0 || c.tcp[0] > m.a1 || c.tcp[1] < m.b0 || c.tcp[1] > m.b1;
  if (outside) { drawScene(c); return; } // the TCP left the picture: a new frame around both
  const x = m.x(c.tcp[0]), y = m.y(c.tcp[1]);
  c.tcpMark.setAttribute("transform", `translate(${x.toFixed(2)},${y.toFixed(2)})`);
  c.tcpMark.dataset.a = c.tcp[0];
  c.tcpMark.dataset.b = c.tcp[1];
  const scenePath = c.scene.path.length ? c.scene.path[c.scene.path.length - 1] : [];
  const from = scenePath.length ? [scenePath[scenePath.length - 1]] : [];
  c.tailLine.setAttribute("points", [...from, ...c.tail].map((p) => `${m.x(p[0]).toFixed(2)},${m.y(p[1]).toFixed(2)}`).join(" "));
  if (c.sm && c.tcp[2] !== null) {
    // s goes on from the scene's position by the distance travelled in the base plane since
    const sNow = (c.scene.position ? c.scene.position[3] : 0) + c.tailS;
    c.sideTcp.setAttribute("cx", c.sm.x(sNow).toFixed(2));
    c.sideTcp.setAttribute("cy", c.sm.y(c.tcp[2]).toFixed(2));
  }
}

// --- the stream ----------------------------------------------------------------------------------
function onHello(hello) {
  state.hello = hello;
  setText(document.getElementById("machine"), `machine ${hello.machine}`);
  setText(document.getElementById("clock"), hello.clock);
  document.title = `hli-server ${hello.machine}`;
  const holder = document.getElementById("channels");
  if (!state.channels.size) {
    for (const ch of hello.channels) {
      const c = channelCard(ch);
      state.channels.set(ch.number, c);
      holder.append(c.card);
    }
  }
  if (hello.read_only) say("the server runs --read-only: actions are refused", "error");
  else if (hello.token && !state.token) askToken("this server needs its API token for actions and its events");
}

function onScene(scene) {
  const c = state.channels.get(scene.channel);
  if (!c) return;
  c.scene = scene;
  c.tail = [];
  c.tailS = 0;
  if (scene.position) c.tcp = scene.position.slice(0, 3);
  drawScene(c);
}

// the picture follows every state (20 Hz); the numbers and lists, which nobody reads faster, 5 times a
// second (each text change costs the browser a layout and a paint)
const NUMBERS_EVERY_MS = 200;
let latestState = null;
setInterval(() => {
  if (latestState) showNumbers(latestState);
  latestState = null;
}, NUMBERS_EVERY_MS);

function onState(s) {
  latestState = s;
  const axes = new Map(s.axes.map((a) => [a.name, a]));
  for (const ch of s.channels) {
    const c = state.channels.get(ch.number);
    if (!c || !c.scene) continue;
    const v = c.scene.view;
    const get = (name) => (name === null ? null : axes.get(name) ? axes.get(name).command_mm : null);
    const tcp = [get(v.a), get(v.b), get(v.height)];
    if (tcp[0] === null || tcp[1] === null) continue;
    if (c.tcp) {
      const moved = Math.hypot(tcp[0] - c.tcp[0], tcp[1] - c.tcp[1]);
      if (moved > 0 || (tcp[2] !== null && tcp[2] !== c.tcp[2])) {
        c.tailS += moved;
        const n = c.tail.length;
        if (n >= 2 && onLine(c.tail[n - 2], c.tail[n - 1], tcp)) c.tail[n - 1] = tcp; // a straight move: 2 points
        else c.tail.push(tcp);
        if (c.tail.length > TAIL_POINTS) c.tail.shift();
      } else {
        continue; // nothing moved: nothing to draw
      }
    }
    c.tcp = tcp;
    drawLive(c);
  }
}

function showNumbers(s) {
  setText(document.getElementById("cycle"), String(s.cycle));
  setText(document.getElementById("time"), `${num(s.time_s, 3)} s`);
  setText(document.getElementById("dropped"), String(s.dropped));
  for (const ch of s.channels) {
    const c = state.channels.get(ch.number);
    if (!c) continue;
    const id = (x) => document.getElementById(`ch${ch.number}-${x}`);
    setText(id("mode"), ch.mode);
    const badge = id("state");
    setText(badge, ch.program_state_name);
    if (badge.className !== `badge ${ch.program_state_name}`) badge.className = `badge ${ch.program_state_name}`;
    setText(id("progname"), ch.program || "-");
    setText(id("block"), ch.block ? `${ch.block} (line ${ch.line})` : "-");
    setText(id("holds"), ch.holds.length ? ch.holds.join(", ") : "none");
    setText(id("override-state"), ch.override_percent === null ? "-" : `${ch.override_percent} %${ch.feedhold ? ", feedhold" : ""}`);
    const kin = ch.kinematic;
    setText(id("kinematic"), !kin ? "-" : kin.active ? `ID ${kin.id} on (#TRAFO ON)` : "off");
    setText(id("tcp"), !kin ? "-" : kin.tool_tip_mm.map((v) => num(v, 3)).join(" / ") + " mm");
    showOverride(id("override"), id("override-value"), ch.override_percent, s.cycle);
    c.feedhold = Boolean(ch.feedhold);
    id("feedhold").classList.toggle("on", c.feedhold);
    id("auto").classList.toggle("on", ch.mode === "automatic");
    id("manual").classList.toggle("on", ch.mode === "manual");
  }
  axisTable(s.axes);
  pairTable(s.pairs);
  alarmList(s.alarms);
  externalTable(s.external || []);
}

// the slider at the override in effect: not while the operator moves it, and not before the cycle that
// latches what the page set (the answer's effective_cycle), so that it never jumps back under the hand
function showOverride(slider, text, percent, cycle) {
  if (percent === null || percent === undefined || slider.dataset.touched) return;
  if (slider.dataset.until !== undefined) {
    if (cycle < Number(slider.dataset.until)) return;
    delete slider.dataset.until;
  }
  const value = String(Math.round(percent));
  if (slider.value !== value) slider.value = value;
  slider.setAttribute("value", value); // also in the DOM (a saved or dumped page shows it)
  setText(text, `${value} %`);
}

// the V.E. variables (N-05): one row each, the value as the engine's store holds it
function externalTable(variables) {
  const text = JSON.stringify(variables);
  if (text === state.lastExternal) return;
  state.lastExternal = text;
  const body = document.querySelector("#external tbody");
  body.replaceChildren();
  if (!variables.length) body.append(el("tr", {}, el("td", { colspan: 5, text: "no V.E. variables configured" })));
  for (const v of variables) {
    // a STRING's text in quotes, so that "" and "12" are not taken for nothing and a number
    const shownValue = (x) => (typeof x === "string" ? JSON.stringify(x) : String(x));
    let value = shownValue(v.value);
    if (Array.isArray(v.value)) {
      const shown = v.value.slice(0, EXTERNAL_ELEMENTS_SHOWN).map(shownValue).join(", ");
      value = `[${shown}${v.value.length > EXTERNAL_ELEMENTS_SHOWN ? `, … (${v.value.length})` : ""}]`;
    }
    const dims = v.dims.length ? `[${v.dims.join(",")}]` : "";
    body.append(el("tr", { "data-variable": v.name },
      el("th", { text: v.name }), el("td", { text: v.channel === null ? "global" : `channel ${v.channel}` }),
      el("td", { text: `${v.type}${dims}` }), el("td", { class: "value", text: value }),
      el("td", { text: v.symbol })));
  }
}

// #MSG of the NC programs (N-07)
function ncMessage(ev) {
  const list = document.getElementById("nc-messages");
  const where = [ev.channel ? `channel ${ev.channel}` : "", ev.data.program, ev.data.line ? `line ${ev.data.line}` : "", ev.data.block || ""]
    .filter(Boolean).join(", ");
  list.prepend(el("li", { class: "nc-message" },
    el("span", { class: "when", text: `${num(ev.time_s, 3)} s` }), " ",
    el("span", { class: "text", text: ev.data.text }), where ? ` (${where})` : "", ev.data.save ? " [saved]" : ""));
  while (list.children.length > MESSAGES_SHOWN) list.lastChild.remove();
}

function axisTable(axes) {
  const body = document.querySelector("#axes tbody");
  for (const a of axes) {
    let row = state.axisRows.get(a.name);
    if (!row) {
      row = axisRow(a.name);
      state.axisRows.set(a.name, row);
      body.append(row.tr);
    }
    setText(row.cells.command, num(a.command_mm));
    setText(row.cells.actual, num(a.actual_mm));
    setText(row.cells.fe, num(a.following_error_mm, 4));
    setText(row.cells.velocity, num(a.velocity_mm_s, 1));
    const flags = [a.referenced ? "referenced" : a.referencing ? "referencing" : "not referenced"];
    if (a.in_position) flags.push("in position");
    if (a.moving) flags.push("moving");
    if (a.error) flags.push("ERROR");
    setText(row.cells.status, flags.join(", "));
    row.tr.classList.toggle("error", a.error);
    for (const side of ["low", "high"]) {
      const d = a.dyn_pos_limit[side];
      setText(row.cells[side], d.enabled || d.state ? `${num(d.limit_mm)} · ${d.state_name}` : d.state_name);
      if (row.cells[side].className !== `dpl s${d.state}`) row.cells[side].className = `dpl s${d.state}`;
    }
    setText(row.cells.brake, a.collision.active ? num(a.collision.brake_dist_mm) : "-");
  }
}

function axisRow(name) {
  const cells = {};
  const tr = el("tr", { id: `axis-${name}` });
  const channel = state.hello ? state.hello.channels.find((c) => c.axes.includes(name)) : null;
  tr.append(el("th", { text: name }), el("td", { text: channel ? String(channel.number) : "-" }));
  for (const key of ["command", "actual", "fe", "velocity", "status", "low", "high", "brake"]) {
    cells[key] = el("td", { class: key });
    tr.append(cells[key]);
  }
  const what = (w) => `axis ${name}: ${w}`;
  const faults = el("td", { class: "faults" },
    el("button", { type: "button", text: "drive error", title: "inject a drive error (A3-05)",
      onclick: () => api("POST", `/api/axes/${name}/faults`, { drive_error: true }, what("drive error")) }),
    el("button", { type: "button", text: "encoder stuck", title: "freeze the measured position",
      onclick: () => api("POST", `/api/axes/${name}/faults`, { encoder_stuck: true }, what("encoder stuck")) }),
    el("button", { type: "button", text: "clear", title: "clear all injected faults",
      onclick: () => api("DELETE", `/api/axes/${name}/faults`, undefined, what("faults cleared")) }),
    el("button", { type: "button", text: "reference", title: "reference (home) the axis",
      onclick: () => api("POST", `/api/axes/${name}/reference`, undefined, what("reference")) }),
  );
  tr.append(faults);
  return { tr, cells };
}

function pairTable(pairs) {
  const text = JSON.stringify(pairs);
  if (text === state.lastPairs) return;
  state.lastPairs = text;
  const body = document.querySelector("#pairs tbody");
  body.replaceChildren();
  if (!pairs.length) body.append(el("tr", {}, el("td", { colspan: 7, text: "no collision pairs configured" })));
  for (const p of pairs) {
    const margin = p.distance - p.brake_master - p.brake_partner - p.min_distance;
    const st = p.stopped ? "STOPPED (P-ERR-70092)" : p.latched ? "latched: move apart" : p.monitoring ? "monitored" : "not monitored (not referenced)";
    body.append(el("tr", { class: p.stopped ? "error" : "" },
      el("th", { text: `${p.master}/${p.partner}` }), el("td", { text: num(p.distance) }), el("td", { text: num(p.min_distance) }),
      el("td", { text: num(p.brake_master) }), el("td", { text: num(p.brake_partner) }),
      el("td", { class: margin < 0 ? "neg" : "", text: num(margin) }), el("td", { text: st })));
  }
}

function alarmItem(a) {
  const where = [a.channel ? `channel ${a.channel}` : "", a.line ? `line ${a.line}` : "", a.block || "", a.axis || ""].filter(Boolean).join(", ");
  return el("li", { class: `alarm ${a.severity}`, "data-alarm": a.id },
    el("strong", { text: `${a.severity} ${a.id}` }), where ? ` (${where}) ` : " ", a.message);
}

function alarmList(alarms) {
  const text = JSON.stringify(alarms);
  if (text === state.lastAlarms) return;
  state.lastAlarms = text;
  const list = document.getElementById("alarms");
  list.replaceChildren();
  if (!alarms.length) list.append(el("li", { class: "none", text: "no active alarm" }));
  for (const a of alarms) list.append(alarmItem(a));
}

// `live`: from the stream (an alarm goes to the history too); else one of the events the page was
// served with (the history comes from /api/alarms)
function onEvent(ev, live = true) {
  const list = document.getElementById("events");
  const data = Object.entries(ev.data || {}).filter(([k]) => k !== "alarm").map(([k, v]) => `${k}=${typeof v === "object" ? JSON.stringify(v) : v}`).join(" ");
  const text = ev.kind === "alarm" ? `${ev.data.alarm.severity} ${ev.data.alarm.id}: ${ev.data.alarm.message}` : data;
  list.prepend(el("li", { class: `event ${ev.kind}` },
    el("span", { class: "when", text: `${num(ev.time_s, 3)} s` }), " ",
    el("span", { class: "kind", text: ev.kind }), ev.channel ? ` ch${ev.channel} ` : " ", text));
  while (list.children.length > EVENTS_SHOWN) list.lastChild.remove();
  if (ev.kind === "nc_message") ncMessage(ev);
  if (ev.kind === "alarm" && live) {
    const history = document.getElementById("alarm-history");
    history.prepend(alarmItem(ev.data.alarm));
    while (history.children.length > HISTORY_SHOWN) history.lastChild.remove();
  }
}

async function loadHistory() {
  try {
    const answer = await fetch("/api/alarms");
    const data = await answer.json();
    const history = document.getElementById("alarm-history");
    for (const a of data.history.slice(-HISTORY_SHOWN).reverse()) history.append(alarmItem(a));
  } catch (_) { /* the stream will tell */ }
}

function liveUrl() {
  return state.token ? "/api/live?access_token=" + encodeURIComponent(state.token) : "/api/live";
}

function connect() {
  const conn = document.getElementById("conn");
  if (state.source) state.source.close();
  const source = new EventSource(liveUrl());
  state.source = source;
  const parse = (handler) => (msg) => {
    try { handler(JSON.parse(msg.data)); } catch (err) { console.error(err); }
  };
  source.addEventListener("open", () => { conn.textContent = "live"; conn.className = "conn ok"; });
  source.addEventListener("error", () => {
    if (source.readyState === EventSource.CLOSED) {
      conn.textContent = "closed (the server refused the stream: too many open pages?); reload";
      conn.className = "conn bad";
    } else {
      conn.textContent = "reconnecting…";
      conn.className = "conn wait";
    }
  });
  source.addEventListener("hello", parse(onHello));
  source.addEventListener("scene", parse(onScene));
  source.addEventListener("state", parse(onState));
  source.addEventListener("event", parse(onEvent));
  source.addEventListener("dropped", parse((d) => say(`this page lost ${d.dropped} events (it read too slowly)`, "error")));
}

// the machine as it was when the page was served: drawn at once, before the stream says anything
function drawInitial() {
  const block = document.getElementById("initial");
  if (!block) return;
  let data;
  try { data = JSON.parse(block.textContent); } catch (err) { console.error(err); return; }
  onHello(data.hello);
  for (const scene of data.scenes) onScene(scene);
  onState(data.state);
  showNumbers(data.state);
  for (const ev of data.events) onEvent(ev, false);
  if (data.recording !== undefined) showRecording(data.recording);
  // what the page shows until the stream opens: the machine as served, not "no data"
  const conn = document.getElementById("conn");
  if (conn.className === "conn wait") {
    conn.textContent = `as served at cycle ${data.state.cycle}; the stream is connecting…`;
  }
}

// --- recording the session (docs/record-replay.md) -----------------------------------------------
function showRecording(st) {
  const button = document.getElementById("record");
  const status = document.getElementById("record-status");
  state.recording = !!(st && st.recording);
  button.textContent = state.recording ? "■ Stop recording" : "● Record";
  button.classList.toggle("on", state.recording);
  if (!st) return;
  if (st.recording) {
    const kb = (st.bytes_written / 1024).toFixed(0);
    status.textContent = `recording ${st.name}: ${st.cycles} cycles since cycle ${st.started_cycle}, ${kb} KiB`;
  } else {
    status.textContent = st.error ? `not recording (${st.error})` : "not recording";
  }
}

async function pollRecording() {
  try {
    const answer = await fetch("/api/recording");
    if (answer.ok) showRecording(await answer.json());
  } catch (_) { /* the stream will tell */ }
}

function setUpRecorder() {
  document.getElementById("record").addEventListener("click", async () => {
    const data = state.recording
      ? await api("POST", "/api/recording/stop", undefined, "stop recording")
      : await api("POST", "/api/recording/start", {}, "record");
    if (data) {
      showRecording(data);
      if (!data.recording && data.name) {
        say(`recorded ${data.name}: download it from /api/recordings/${data.name}; hli-server replay FILE replays it`);
      }
    }
  });
  pollRecording();
  setInterval(pollRecording, 1000);
}

setUpToken();
setUpRecorder();
drawInitial();
loadHistory();
connect();
