// The fleet operator console: the map and tables from the websocket's pushes, and every command
// as a request on the same socket (fleet_planner/ros/console/server.py says the protocol).
"use strict";

const SVG = "http://www.w3.org/2000/svg";
const COLOURS = {idle: "#607d8b", driving: "#1e88e5", waiting: "#fb8c00", picking: "#43a047", placing: "#43a047",
                 charging: "#8e24aa", offline: "#000", error: "#b71c1c"};
let ws = null, layout = null, state = null, nextRef = 1, retry = 500;
const pending = new Map();

function $(id) { return document.getElementById(id); }
function el(tag, attrs, parent) {
  const e = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (parent) parent.appendChild(e);
  return e;
}
function html(tag, attrs, text) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
}

// -- the socket ---------------------------------------------------------------------------------
function connect() {
  ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws");
  ws.onopen = () => { $("conn").textContent = "live"; $("conn").className = "ok"; retry = 500; };
  ws.onclose = () => {
    $("conn").textContent = "disconnected"; $("conn").className = "bad";
    setTimeout(connect, retry); retry = Math.min(retry * 2, 5000);
  };
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    if (msg.type === "layout") drawLayout(msg);
    else if (msg.type === "state") drawState(msg);
    else if (msg.type === "reply") settle(msg);
  };
}

function send(request, what) {
  const ref = nextRef++;
  pending.set(ref, what);
  if (!ws || ws.readyState !== WebSocket.OPEN) { settle({ref, ok: false, message: "not connected"}); return; }
  ws.send(JSON.stringify({...request, ref}));
}

function settle(msg) {
  const what = pending.has(msg.ref) ? pending.get(msg.ref) : "request";
  pending.delete(msg.ref);
  if (what === null && msg.ok) return;  // drive commands: only failures are shown
  const li = html("li", {class: msg.ok ? "ok" : "fail"}, `${what || "drive"}: ${msg.message}`);
  $("log").prepend(li);
  while ($("log").children.length > 50) $("log").lastChild.remove();
}

function command(fields, what) { send({type: "command", command: fields}, what || fields.command); }

// -- the map ------------------------------------------------------------------------------------
function drawLayout(msg) {
  layout = msg;
  const res = msg.resolution, w = msg.width * res, h = msg.height * res;
  $("wh-name").textContent = `- ${msg.name}`;
  $("map").setAttribute("viewBox", `0 0 ${w} ${h}`);
  const map = $("layer-map"); map.replaceChildren();
  el("rect", {x: 0, y: 0, width: w, height: h, fill: "#fafafa"}, map);
  let d = "";
  for (const [col, row, len] of msg.blocked) d += `M${col * res} ${row * res}h${len * res}v${res}h${-len * res}z`;
  el("path", {d, fill: "#455a64"}, map);
  const st = $("layer-stations"); st.replaceChildren();
  const colours = {chute: "#ffb300", storage: "#26a69a", charger: "#ab47bc"};
  for (const s of msg.stations) {
    const g = el("g", {class: "station", id: `station-${s.name}`}, st);
    el("rect", {x: s.x - 0.25, y: s.y - 0.25, width: 0.5, height: 0.5, fill: "none",
                stroke: colours[s.type] || "#000", "stroke-width": 0.08}, g);
    el("text", {x: s.x, y: s.y + 0.65, "font-size": 0.3, fill: "#333", "text-anchor": "middle"}, g).textContent = s.name;
  }
  for (const p of msg.parking) {
    const g = el("g", {class: "parking", id: `parking-${p.name}`}, st);
    el("rect", {x: p.x - 0.25, y: p.y - 0.25, width: 0.5, height: 0.5, fill: "none", stroke: "#777",
                "stroke-dasharray": "0.1 0.1", "stroke-width": 0.05}, g);
    el("text", {x: p.x, y: p.y + 0.6, "font-size": 0.28, fill: "#777", "text-anchor": "middle"}, g).textContent = p.name;
  }
  const chutes = msg.stations.filter((s) => s.type === "chute").map((s) => s.name);
  const tags = msg.stations.filter((s) => s.type === "storage").flatMap((s) => [s.name, ...s.tags]);
  fill($("f-pick"), chutes);
  fill($("f-place"), tags);
}

function fill(select, names) {
  const keep = select.value;
  select.replaceChildren(...names.map((n) => html("option", {value: n}, n)));
  if (names.includes(keep)) select.value = keep;
}

function drawState(msg) {
  state = msg;
  $("clock").textContent = msg.t.toFixed(1);
  const btn = $("estop-btn");
  btn.textContent = msg.estop ? "RELEASE E-STOP" : "E-STOP";
  btn.classList.toggle("engaged", msg.estop);
  btn.dataset.engaged = msg.estop ? "1" : "0";
  $("fleet-state").textContent = msg.estop ? "E-STOP ENGAGED" : msg.fleet_paused ? "fleet paused" : "running";
  drawRobots(msg.robots);
  drawObstacles(msg.obstacles);
  robotsTable(msg.robots);
  jobsTable(msg.jobs);
}

function drawRobots(robots) {
  const layer = $("layer-robots"), paths = $("layer-paths");
  const seen = new Set();
  for (const r of robots) {
    seen.add(r.id);
    let g = $(`robot-${r.id}`);
    if (!g) {
      g = el("g", {class: "robot", id: `robot-${r.id}`}, layer);
      el("circle", {class: "ring", r: r.radius + 0.12, fill: "none", "stroke-width": 0.1}, g);
      el("circle", {class: "body", r: r.radius, stroke: "#000", "stroke-width": 0.03}, g);
      el("line", {class: "heading", x1: 0, y1: 0, x2: r.radius, y2: 0, stroke: "white", "stroke-width": 0.06}, g);
      el("text", {class: "label", x: r.radius + 0.1, y: -r.radius, "font-size": 0.45}, g).textContent = r.id;
      el("polyline", {class: "path", id: `path-${r.id}`, fill: "none", stroke: "#1e88e5", "stroke-width": 0.06,
                      "stroke-dasharray": "0.2 0.1", opacity: 0.7}, paths);
      el("g", {class: "holds", id: `holds-${r.id}`}, paths);
    }
    g.setAttribute("transform", `translate(${r.x} ${r.y}) rotate(${r.yaw * 180 / Math.PI})`);
    g.dataset.x = r.x; g.dataset.y = r.y; g.dataset.mode = r.mode;
    g.dataset.paused = r.paused ? "1" : "0"; g.dataset.manual = r.manual ? "1" : "0";
    g.dataset.estop = r.estop ? "1" : "0";
    g.querySelector(".label").setAttribute("transform", `rotate(${-r.yaw * 180 / Math.PI})`);
    g.querySelector(".body").setAttribute("fill", r.stale ? "#bbb" : COLOURS[r.mode] || "#000");
    const ring = g.querySelector(".ring");
    ring.setAttribute("stroke", r.estop ? "#c62828" : r.manual ? "#d81b60" : r.paused ? "#ff6f00" : "none");
    $(`path-${r.id}`).setAttribute("points", r.path.map((p) => p.join(",")).join(" "));
    const holds = $(`holds-${r.id}`); holds.replaceChildren();
    for (const [x, y] of r.holds) el("rect", {x: x - 0.12, y: y - 0.12, width: 0.24, height: 0.24, fill: "#000"}, holds);
  }
  for (const g of [...layer.children]) {
    const id = g.id.slice(6);
    if (!seen.has(id)) { g.remove(); $(`path-${id}`)?.remove(); $(`holds-${id}`)?.remove(); }
  }
}

function drawObstacles(obstacles) {
  const layer = $("layer-obstacles"); layer.replaceChildren();
  for (const o of obstacles) {
    const g = el("g", {class: "obstacle", id: `obstacle-${o.id}`}, layer);
    el("circle", {cx: o.x, cy: o.y, r: o.radius, fill: "#9e9e9e", opacity: 0.8}, g);
    el("text", {x: o.x + o.radius, y: o.y - o.radius, "font-size": 0.35, fill: "#555"}, g).textContent = o.kind;
  }
}

// -- the tables ---------------------------------------------------------------------------------
function button(text, cls, onclick, title) {
  const b = html("button", {class: cls, type: "button", title: title || text}, text);
  b.addEventListener("click", onclick);
  return b;
}

function robotsTable(robots) {
  const body = $("robots").tBodies[0];
  const names = layout ? [...layout.stations.map((s) => s.name), ...layout.parking.map((p) => p.name)] : [];
  for (const r of robots) {
    let tr = $(`row-${r.id}`);
    if (!tr) {
      tr = html("tr", {id: `row-${r.id}`});
      for (const c of ["id", "kind", "mode", "battery", "job"]) tr.appendChild(html("td", {class: c}));
      const td = html("td", {class: "commands"});
      td.append(button("pause", "pause", () => command({command: "pause", robot_id: r.id}, `pause ${r.id}`)),
                button("resume", "resume", () => command({command: "resume", robot_id: r.id}, `resume ${r.id}`)),
                button("manual", "manual-on", () => send({type: "manual", robot_id: r.id, on: true}, `manual ${r.id} on`),
                       "switch to manual drive (drive pad)"),
                button("auto", "manual-off", () => send({type: "manual", robot_id: r.id, on: false}, `manual ${r.id} off`),
                       "leave manual drive: re-join the plan"));
      const sel = html("select", {class: "station"});
      td.appendChild(sel);
      td.appendChild(button("send", "send", () => command({command: "send", robot_id: r.id, station: sel.value},
                                                          `send ${r.id} to ${sel.value}`)));
      tr.appendChild(td);
      body.appendChild(tr);
      const pad = $("drive-robot");
      pad.appendChild(html("option", {value: r.id}, r.id));
    }
    const sel = tr.querySelector("select.station");
    if (sel.options.length !== names.length) fill(sel, names);
    const flags = [r.paused && "paused", r.manual && "manual", r.estop && "e-stop"].filter(Boolean).join(", ");
    tr.querySelector(".id").textContent = r.id;
    tr.querySelector(".kind").textContent = r.kind;
    tr.querySelector(".mode").textContent = r.mode + (flags ? ` (${flags})` : "");
    tr.querySelector(".battery").textContent = `${Math.round(r.battery * 100)}%`;
    tr.querySelector(".job").textContent = r.job || "";
  }
}

function jobsTable(jobs) {
  const body = $("jobs").tBodies[0];
  for (const j of jobs) {
    let tr = $(`job-${j.id}`);
    if (!tr) {
      tr = html("tr", {id: `job-${j.id}`});
      for (const c of ["id", "pick", "place", "priority", "deadline", "state", "robot"]) tr.appendChild(html("td", {class: c}));
      const td = html("td", {class: "commands"});
      const prio = html("input", {class: "prio", type: "number", step: "1", value: j.priority ?? 0});
      td.append(button("cancel", "cancel", () => command({command: "cancel", task_id: j.id}, `cancel ${j.id}`)), prio,
                button("set", "set-prio", () => command({command: "priority", task_id: j.id,
                                                         priority: parseInt(prio.value, 10)}, `priority ${j.id}`),
                       "set the priority"));
      tr.appendChild(td);
      body.prepend(tr);
    }
    tr.querySelector(".id").textContent = j.id;
    tr.querySelector(".pick").textContent = j.pick || "";
    tr.querySelector(".place").textContent = j.place || "";
    tr.querySelector(".priority").textContent = j.priority ?? "";
    tr.querySelector(".deadline").textContent = j.deadline != null ? j.deadline.toFixed(0) : "";
    tr.querySelector(".state").textContent = (j.state || "?") + (j.late ? " (late)" : "");
    tr.querySelector(".state").title = j.reason || "";
    tr.querySelector(".robot").textContent = j.robot || "";
    tr.classList.toggle("late", !!j.late);
    tr.dataset.state = j.state || "";
  }
}

// -- the controls -------------------------------------------------------------------------------
$("estop-btn").addEventListener("click", () => {
  const engaged = state && state.estop;
  command({command: engaged ? "release" : "estop"}, engaged ? "release e-stop" : "E-STOP");
});
$("pause-fleet-btn").addEventListener("click", () => command({command: "pause"}, "pause fleet"));
$("resume-fleet-btn").addEventListener("click", () => command({command: "resume"}, "resume fleet"));

$("submit-form").addEventListener("submit", (ev) => {
  ev.preventDefault();
  const needs = ["manipulator", "forklift"].filter((n) => $(`f-${n}`).checked);
  const task = {pick: $("f-pick").value, place: $("f-place").value, needs,
                payload_kg: parseFloat($("f-payload").value || "0"), priority: parseInt($("f-priority").value || "0", 10)};
  const within = $("f-deadline").value;
  if (within !== "" && state) task.deadline = state.t + parseFloat(within);
  if ($("f-id").value.trim()) task.id = $("f-id").value.trim();
  send({type: "submit", task}, `submit ${task.id || "job"}`);
});

// the drive pad: while a button is held, a velocity command 10 times a second (the robot stops by
// itself half a second after the last one)
let driving = null;
function drive(linear, angular) {
  stopDriving();
  const tick = () => {
    const rid = $("drive-robot").value;
    if (rid) send({type: "drive", robot_id: rid, linear, angular}, null);
  };
  tick();
  driving = setInterval(tick, 100);
}
function stopDriving() { if (driving) { clearInterval(driving); driving = null; } }
const speed = () => parseFloat($("drive-speed").value || "0.3");
for (const [id, f] of [["drive-fwd", () => drive(speed(), 0)], ["drive-back", () => drive(-speed(), 0)],
                       ["drive-left", () => drive(0, 0.8)], ["drive-right", () => drive(0, -0.8)]]) {
  const b = $(id);
  b.addEventListener("mousedown", f);
  b.addEventListener("touchstart", f);
}
// released anywhere (the page re-lays itself out under a held pointer as it updates, so leaving the
// button is not a release), or the window loses the pointer: stop; a lost release is caught by the
// robot's dead man's switch
for (const end of ["mouseup", "touchend", "touchcancel"]) document.addEventListener(end, stopDriving);
window.addEventListener("blur", stopDriving);

connect();
