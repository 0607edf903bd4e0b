// The hub's live court view: draws the venue once, then each snapshot the hub's WebSocket sends
// (about 10 per second). Venue frame in metres, y up; the SVG's user unit is one metre with y
// negated. `window.courtView` holds what the page last drew (the tests read it).
"use strict";

const SVG = "http://www.w3.org/2000/svg";
const MARKER_S = 5;  // how long a correction's marker stays on the court
const EVENTS_SHOWN = 30;
const STALE_S = 2;  // an input or status older than this is shown as stale
const PALETTE = ["#e53935", "#1e88e5", "#43a047", "#fb8c00", "#8e24aa", "#00acc1", "#6d4c41", "#c0ca33",
                 "#d81b60", "#3949ab", "#00897b", "#f4511e"];
const view = { venue: null, state: null, ticks: 0, colors: {}, agents: {} };
window.courtView = view;

function el(name, attrs, parent) {
  const node = document.createElementNS(SVG, name);
  for (const [key, value] of Object.entries(attrs || {})) node.setAttribute(key, value);
  if (parent) parent.appendChild(node);
  return node;
}

function fmt(value, digits = 2) {
  return value === null || value === undefined ? "-" : value.toFixed(digits);
}

function bounds(venue) {
  const xs = [0, venue.length_m], ys = [0, venue.width_m];
  if (venue.layout === "floor") {
    xs.length = 0; ys.length = 0;
    for (const polygon of venue.floor_plan) for (const ring of polygon) for (const [x, y] of ring) { xs.push(x); ys.push(y); }
    for (const p of [...venue.map_points, ...venue.stands, ...venue.beacons]) { xs.push(p.x); ys.push(p.y); }
    if (!xs.length) { xs.push(0, venue.length_m); ys.push(0, venue.width_m); }
  }
  return { x0: Math.min(...xs), x1: Math.max(...xs), y0: Math.min(...ys), y1: Math.max(...ys) };
}

function drawCourtLines(venue, layer) {
  const L = venue.length_m, W = venue.width_m;
  el("rect", { class: "line", x: 0, y: -W, width: L, height: W }, layer);
  if (venue.sport === "swim") {  // lane ropes every 2.5 m across the pool
    for (let y = 2.5; y < W; y += 2.5) el("line", { class: "line", x1: 0, y1: -y, x2: L, y2: -y }, layer);
    return;
  }
  // Basketball (FIBA, also IWBF): halfway line, centre circle, the keys, baskets and 3-point lines.
  el("line", { class: "line", x1: L / 2, y1: 0, x2: L / 2, y2: -W }, layer);
  el("circle", { class: "line", cx: L / 2, cy: -W / 2, r: 1.8 }, layer);
  for (const [base, dir] of [[0, 1], [L, -1]]) {
    const basket = base + dir * 1.575;
    el("rect", { class: "line", x: Math.min(base, base + dir * 5.8), y: -(W / 2 + 2.45), width: 5.8, height: 4.9 }, layer);
    el("circle", { class: "line", cx: base + dir * 5.8, cy: -W / 2, r: 1.8 }, layer);
    el("circle", { class: "line", cx: basket, cy: -W / 2, r: 0.225 }, layer);
    // 3-point line: straight 0.9 m in from each sideline, then the 6.75 m arc round the basket
    const side = W / 2 - 0.9, reach = Math.sqrt(Math.max(0, 6.75 * 6.75 - side * side)), tip = basket + dir * reach;
    const sweep = dir > 0 ? 0 : 1;  // the arc bulges towards the halfway line
    el("path", { class: "line", d: `M ${base} ${-0.9} L ${tip} ${-0.9} A 6.75 6.75 0 0 ${sweep} ${tip} ${-(W - 0.9)} ` +
      `L ${base} ${-(W - 0.9)}` }, layer);
  }
}

function drawVenue(venue) {
  view.venue = venue;
  document.getElementById("venue-name").textContent = venue.name;
  document.body.dataset.layout = venue.layout;
  const b = bounds(venue), pad = 1.5;
  const svg = document.getElementById("court");
  svg.setAttribute("viewBox", `${b.x0 - pad} ${-(b.y1 + pad)} ${b.x1 - b.x0 + 2 * pad} ${b.y1 - b.y0 + 2 * pad}`);
  const floor = document.getElementById("layer-floor"), lines = document.getElementById("layer-lines");
  const fixtures = document.getElementById("layer-fixtures");
  for (const layer of [floor, lines, fixtures]) layer.replaceChildren();
  for (const polygon of venue.floor_plan) {
    const d = polygon.map((ring) => "M " + ring.map(([x, y]) => `${x} ${-y}`).join(" L ") + " Z").join(" ");
    el("path", { class: "floor", d, "fill-rule": "evenodd" }, floor);
  }
  if (venue.layout === "court") drawCourtLines(venue, lines);
  for (const p of venue.map_points) {
    el("circle", { class: "map-point", cx: p.x, cy: -p.y, r: 0.15 }, fixtures);
    el("text", { class: "fixture-label", x: p.x + 0.25, y: -p.y - 0.2 }, fixtures).textContent = p.id;
  }
  for (const beacon of venue.beacons) {
    el("circle", { class: "beacon-zone", cx: beacon.x, cy: -beacon.y, r: beacon.radius_m }, fixtures);
    el("circle", { class: "beacon", cx: beacon.x, cy: -beacon.y, r: 0.2, "data-beacon": beacon.id }, fixtures);
    el("text", { class: "fixture-label", x: beacon.x + 0.3, y: -beacon.y + 0.6 }, fixtures).textContent = beacon.id;
  }
  for (const stand of venue.stands) {
    el("rect", { class: "stand", x: stand.x - 0.2, y: -stand.y - 0.2, width: 0.4, height: 0.4, "data-stand": stand.id }, fixtures);
    el("text", { class: "fixture-label", x: stand.x + 0.3, y: -stand.y - 0.3 }, fixtures).textContent = `QR ${stand.id}`;
  }
  venue.agents.forEach((agent, i) => { view.colors[agent.id] = PALETTE[i % PALETTE.length]; });
}

function agentGlyph(id) {
  if (view.agents[id]) return view.agents[id];
  const layer = document.getElementById("layer-agents");
  const group = el("g", { class: "agent", "data-agent": id }, layer);
  const glyph = {
    group,
    ellipse: el("ellipse", { class: "uncertainty" }, group),
    truth: el("circle", { class: "truth", r: 0.35, visibility: "hidden" }, layer),
    refined: el("circle", { class: "refined", r: 0.1, visibility: "hidden" }, layer),
    body: el("circle", { r: 0.3, fill: view.colors[id] || "#333", stroke: "#fff", "stroke-width": 0.05 }, group),
    heading: el("line", { class: "heading" }, group),
    label: el("text", { class: "agent-label" }, group),
  };
  glyph.label.textContent = id;
  view.agents[id] = glyph;
  return glyph;
}

function drawAgent(id, agent) {
  const live = agent.live;
  const glyph = agentGlyph(id);
  if (!live) { glyph.group.setAttribute("visibility", "hidden"); return; }
  glyph.group.setAttribute("visibility", "visible");
  glyph.group.dataset.x = live.x.toFixed(3);
  glyph.group.dataset.y = live.y.toFixed(3);
  const [cx, cy] = [live.x, -live.y];
  glyph.body.setAttribute("cx", cx); glyph.body.setAttribute("cy", cy);
  glyph.heading.setAttribute("x1", cx); glyph.heading.setAttribute("y1", cy);
  glyph.heading.setAttribute("x2", cx + 0.6 * Math.cos(live.heading));
  glyph.heading.setAttribute("y2", cy - 0.6 * Math.sin(live.heading));
  glyph.label.setAttribute("x", cx + 0.4); glyph.label.setAttribute("y", cy - 0.4);
  if (live.ellipse) {
    const [major, minor, angle] = live.ellipse;
    glyph.ellipse.setAttribute("rx", Math.max(major, 0.01)); glyph.ellipse.setAttribute("ry", Math.max(minor, 0.01));
    glyph.ellipse.setAttribute("transform", `translate(${cx} ${cy}) rotate(${-angle * 180 / Math.PI})`);
    glyph.ellipse.setAttribute("visibility", "visible");
  } else glyph.ellipse.setAttribute("visibility", "hidden");
  for (const [node, pose] of [[glyph.truth, agent.truth], [glyph.refined, agent.refined]]) {
    node.setAttribute("visibility", pose ? "visible" : "hidden");
    if (pose) { node.setAttribute("cx", pose.x); node.setAttribute("cy", -pose.y); }
  }
}

function statusText(agent) {
  const sensors = Object.entries(agent.status);
  if (!sensors.length) {
    if (agent.input_age_s === null) return { text: "no input yet", stale: true };
    return { text: `last input ${fmt(agent.input_age_s, 1)} s ago`, stale: agent.input_age_s > STALE_S };
  }
  let stale = false;
  const parts = sensors.map(([sensor, s]) => {
    const bits = [s.connected ? "connected" : "DISCONNECTED"];
    if (s.battery_pct !== null) bits.push(`battery ${s.battery_pct.toFixed(0)} %`);
    if (s.last_sample_age_s !== null) bits.push(`sample ${fmt(s.last_sample_age_s, 1)} s`);
    if (s.flags.length) bits.push(s.flags.join(" "));
    stale = stale || !s.connected || s.age_s > STALE_S || s.flags.length > 0;
    return `${sensor}: ${bits.join(", ")}`;
  });
  return { text: parts.join("; "), stale };
}

function drawTable(state) {
  const body = document.querySelector("#agents tbody");
  for (const [id, agent] of Object.entries(state.agents)) {
    let row = body.querySelector(`tr[data-agent="${id}"]`);
    if (!row) {
      row = document.createElement("tr");
      row.dataset.agent = id;
      row.innerHTML = "<td class=id></td><td class=x></td><td class=y></td><td class=error></td>" +
        "<td class=mean></td><td class=status></td><td class=corrections></td>";
      row.querySelector(".id").textContent = id;
      row.querySelector(".id").style.color = view.colors[id] || "";
      body.appendChild(row);
    }
    row.querySelector(".x").textContent = agent.live ? fmt(agent.live.x) : "-";
    row.querySelector(".y").textContent = agent.live ? fmt(agent.live.y) : "-";
    row.querySelector(".error").textContent = fmt(agent.error_m);
    row.querySelector(".mean").textContent = fmt(agent.mean_error_m);
    const status = statusText(agent);
    const cell = row.querySelector(".status");
    cell.textContent = status.text;
    cell.classList.toggle("stale", status.stale);
    row.querySelector(".corrections").textContent =
      Object.entries(agent.corrections).map(([kind, n]) => `${kind} ${n}`).join(", ") || "none";
  }
}

function drawEvents(state) {
  const layer = document.getElementById("layer-markers");
  layer.replaceChildren();
  for (const event of state.events) {
    const age = (state.now_ns - event.received_ns) / 1e9;
    if (event.x === null || age > MARKER_S) continue;
    const kindClass = event.kind === "beacon" ? "beacon-kind" : event.kind;
    el("circle", { class: `marker ${kindClass}`, cx: event.x, cy: -event.y, r: 0.4 + 0.25 * age,
                   opacity: Math.max(0.15, 1 - age / MARKER_S), "data-event": event.n }, layer);
  }
  const list = document.getElementById("events");
  const newest = list.firstElementChild ? Number(list.firstElementChild.dataset.n) : 0;
  for (const event of state.events) {
    if (event.n <= newest) continue;
    const item = document.createElement("li");
    item.dataset.n = event.n;
    item.dataset.kind = event.kind;
    const where = event.x === null ? "" : ` at (${fmt(event.x, 1)}, ${fmt(event.y, 1)})`;
    const shift = event.shift ? ` shift ${fmt(Math.hypot(...event.shift))} m` : "";
    const source = event.source ? ` from ${event.source}` : "";
    item.textContent = `${new Date(event.received_ns / 1e6).toLocaleTimeString()} ${event.agent} ${event.kind}` +
      `${source}${where}${shift}`;
    list.prepend(item);
  }
  while (list.children.length > EVENTS_SHOWN) list.lastElementChild.remove();
}

function drawState(state) {
  view.state = state;
  view.ticks += 1;
  for (const [id, agent] of Object.entries(state.agents)) drawAgent(id, agent);
  drawTable(state);
  drawEvents(state);
  const errors = Object.values(state.agents).map((a) => a.mean_error_m).filter((e) => e !== null);
  const team = errors.length ? ` · team mean error ${fmt(errors.reduce((s, e) => s + e, 0) / errors.length)} m` : "";
  const dropped = state.dropped ? ` · view dropped ${state.dropped}` : "";
  document.getElementById("summary").textContent = `${Object.keys(state.agents).length} agents${team}${dropped}`;
  document.body.dataset.ticks = view.ticks;
}

function connect() {
  const socket = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  socket.onopen = () => {
    document.body.dataset.state = "connected";
    document.getElementById("connection").textContent = "live";
  };
  socket.onmessage = (message) => {
    const data = JSON.parse(message.data);
    if (data.type === "venue") drawVenue(data);
    else if (data.type === "state" && view.venue) drawState(data);
  };
  socket.onclose = () => {
    document.body.dataset.state = "closed";
    document.getElementById("connection").textContent = "hub gone: reconnecting";
    setTimeout(connect, 1000);
  };
}

connect();
