// swarmpark operator interface (Hing et al. 2018, Figs. 2-3) in plain JS on a canvas.
// State arrives over the WebSocket /api/ws (a full frame, then deltas); commands go to the
// REST API. World frame: x right, y up, yaw counter-clockwise; angles in degrees here.
"use strict";

const STATE_COLOURS = {
  idle: "#8a939c", moving: "#3ea6ff", parked: "#3fbf5f", stopped: "#f0a020",
  estopped: "#e0242c", teleop: "#a66bff", stuck: "#ff4fd8", lost: "#7d2b2b",
};
const PATH_COLOUR = "#4cd964";
const DETECTED_COLOUR = "#d040ff";
const TRACKED_COLOUR = "#ffd23c";
// Parts of a frame sent only when they change (the server's frames.SLOW_KEYS).
const SLOW_KEYS = ["goals", "paths", "groups", "log", "metrics", "orders", "detected", "robot_info"];
const GAMEPAD_DEADZONE = 0.15;

// ------------------------------------------------------------------ state

const S = {
  world: null,          // GET /api/world
  meta: null,           // GET /api/meta: layout methods, assignment costs, limits
  mapImg: null,         // the occupancy map image
  frame: null,          // latest frame merged with the slow parts
  frames: [],           // recent frames (t_s, estop, robots) for tests and debugging
  selection: new Set(),
  tool: "select",
  drawing: null,        // {kind: "polygon"|"rect"|"box"|"goal", ...}
  boundary: null,       // [[x, y], ...] closed parking boundary (world metres)
  preview: null,        // {goals, ...} or {error}
  previewSeq: 0,
  view: { cx: 0, cy: 0, scale: 40 },   // world point at the canvas centre, px per metre
  pan: null,
  mouse: null,          // last mouse position in world coordinates
  token: sessionStorage.getItem("swarmpark-token") || "",
  secret: sessionStorage.getItem("swarmpark-secret") || "",
  secretRequired: false,
  lastFrameAt: 0,       // performance.now() of the last frame (stale-link banner)
  estopSent: null,      // {at, state: "sent"|"acknowledged"|"applied"|"failed"}
  control: true,
  tokenRequired: false,
  teleop: { robot: null, keys: new Set(), timer: null, last: [0, 0] },
  dirty: true,
  scenarios: [],
};

const $ = (id) => document.getElementById(id);
const canvas = $("map");
const ctx = canvas.getContext("2d");

// ------------------------------------------------------------------ helpers

function toast(msg, ok = false) {
  const t = $("toast");
  t.textContent = msg;
  t.className = ok ? "ok" : "";
  clearTimeout(toast.timer);
  toast.timer = setTimeout(() => t.classList.add("hidden"), ok ? 2000 : 6000);
}

function ids() { return S.world ? S.world.robots.map((r) => r.id) : []; }
function stateName(code) { return S.world ? S.world.states[code] : "?"; }
function deg(r) { return (r * 180) / Math.PI; }
function rad(d) { return (d * Math.PI) / 180; }

async function api(path, body, method = "POST") {
  const headers = { "Content-Type": "application/json" };
  if (S.token) headers.Authorization = "Bearer " + S.token;
  if (S.secret) headers["X-Swarmpark-Secret"] = S.secret;
  let res;
  try {
    res = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  } catch (e) {
    toast("no connection to the server");
    return { ok: false, status: 0, data: null };
  }
  let data = null;
  try { data = await res.json(); } catch (e) { /* empty body */ }
  return { ok: res.ok, status: res.status, data };
}

function why(r) {
  const d = r.data || {};
  if (r.status === 409 && d.reason) return "refused: " + d.reason;
  if (d.message) return d.message;
  if (typeof d.detail === "string") return d.detail;
  return "HTTP " + r.status;
}

// A command: show the reason if it was refused or malformed.
async function command(path, body, okMsg) {
  const r = await api(path, body);
  if (!r.ok) toast(why(r));
  else if (okMsg) toast(okMsg, true);
  return r;
}

// ------------------------------------------------------------------ view transform

function resize() {
  const dpr = window.devicePixelRatio || 1;
  const r = canvas.getBoundingClientRect();
  canvas.width = Math.max(1, Math.round(r.width * dpr));
  canvas.height = Math.max(1, Math.round(r.height * dpr));
  S.dirty = true;
}

function cssSize() { const r = canvas.getBoundingClientRect(); return [r.width, r.height]; }

function toScreen(x, y) {
  const [w, h] = cssSize();
  return [(x - S.view.cx) * S.view.scale + w / 2, h / 2 - (y - S.view.cy) * S.view.scale];
}

function toWorld(px, py) {
  const [w, h] = cssSize();
  return [S.view.cx + (px - w / 2) / S.view.scale, S.view.cy - (py - h / 2) / S.view.scale];
}

function fit() {
  if (!S.world) return;
  const [x0, y0, x1, y1] = S.world.map.bounds_m;
  const [w, h] = cssSize();
  S.view.cx = (x0 + x1) / 2;
  S.view.cy = (y0 + y1) / 2;
  S.view.scale = Math.max(1, 0.94 * Math.min(w / (x1 - x0), h / (y1 - y0)));
  S.dirty = true;
}

function zoomAt(px, py, factor) {
  const [wx, wy] = toWorld(px, py);
  S.view.scale = Math.min(2000, Math.max(0.5, S.view.scale * factor));
  const [nx, ny] = toWorld(px, py);
  S.view.cx += wx - nx;
  S.view.cy += wy - ny;
  S.dirty = true;
}

function eventXY(ev) {
  const r = canvas.getBoundingClientRect();
  return [ev.clientX - r.left, ev.clientY - r.top];
}

// ------------------------------------------------------------------ geometry

function footprintCorners(i, x, y, yawDeg) {
  const fp = S.world.robots[i];
  const r = -fp.pivot_from_rear_m, f = fp.length_m - fp.pivot_from_rear_m, hw = fp.width_m / 2;
  const c = Math.cos(rad(yawDeg)), s = Math.sin(rad(yawDeg));
  return [[r, -hw], [f, -hw], [f, hw], [r, hw]].map(([bx, by]) => [x + c * bx - s * by, y + s * bx + c * by]);
}

function centre(i, x, y, yawDeg) {
  const fp = S.world.robots[i];
  const off = fp.length_m / 2 - fp.pivot_from_rear_m;
  return [x + off * Math.cos(rad(yawDeg)), y + off * Math.sin(rad(yawDeg))];
}

function insidePolygon(pt, poly) {
  let inside = false;
  for (let i = 0, j = poly.length - 1; i < poly.length; j = i++) {
    const [xi, yi] = poly[i], [xj, yj] = poly[j];
    if ((yi > pt[1]) !== (yj > pt[1]) && pt[0] < ((xj - xi) * (pt[1] - yi)) / (yj - yi) + xi) inside = !inside;
  }
  return inside;
}

function robotAt(wx, wy) {
  if (!S.frame) return null;
  const robots = S.frame.robots;
  // Topmost last: search backwards, and accept a few pixels of slack for small skids.
  const slack = 4 / S.view.scale;
  for (let i = robots.length - 1; i >= 0; i--) {
    const [x, y, h] = robots[i];
    const poly = footprintCorners(i, x, y, h);
    if (insidePolygon([wx, wy], poly)) return i;
    const [cx, cy] = centre(i, x, y, h);
    if (Math.hypot(wx - cx, wy - cy) < slack) return i;
  }
  return null;
}

// ------------------------------------------------------------------ drawing

function pathPolygon(pts, close) {
  ctx.beginPath();
  pts.forEach(([x, y], k) => {
    const [sx, sy] = toScreen(x, y);
    if (k === 0) ctx.moveTo(sx, sy); else ctx.lineTo(sx, sy);
  });
  if (close) ctx.closePath();
}

function drawFootprint(i, x, y, h, fill, stroke, width = 1, dash = null) {
  pathPolygon(footprintCorners(i, x, y, h), true);
  if (fill) { ctx.fillStyle = fill; ctx.fill(); }
  if (stroke) {
    ctx.setLineDash(dash || []);
    ctx.strokeStyle = stroke; ctx.lineWidth = width; ctx.stroke();
    ctx.setLineDash([]);
  }
}

function drawArrow(x, y, yawDeg, len, colour, width = 2) {
  const [sx, sy] = toScreen(x, y);
  const ex = sx + len * Math.cos(rad(yawDeg)), ey = sy - len * Math.sin(rad(yawDeg));
  ctx.strokeStyle = colour; ctx.fillStyle = colour; ctx.lineWidth = width;
  ctx.beginPath(); ctx.moveTo(sx, sy); ctx.lineTo(ex, ey); ctx.stroke();
  const a = Math.atan2(ey - sy, ex - sx), hl = Math.min(9, len * 0.45);
  ctx.beginPath();
  ctx.moveTo(ex, ey);
  ctx.lineTo(ex - hl * Math.cos(a - 0.45), ey - hl * Math.sin(a - 0.45));
  ctx.lineTo(ex - hl * Math.cos(a + 0.45), ey - hl * Math.sin(a + 0.45));
  ctx.closePath(); ctx.fill();
}

function draw() {
  const dpr = window.devicePixelRatio || 1;
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  const [w, h] = cssSize();
  ctx.clearRect(0, 0, w, h);
  if (!S.world) return;
  const m = S.world.map;

  // Map image, one pixel per cell (no smoothing: cells stay sharp when zoomed in).
  if (S.mapImg && S.mapImg.complete) {
    const [sx, sy] = toScreen(m.bounds_m[0], m.bounds_m[3]);
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(S.mapImg, sx, sy, (m.bounds_m[2] - m.bounds_m[0]) * S.view.scale,
      (m.bounds_m[3] - m.bounds_m[1]) * S.view.scale);
  }
  for (const poly of S.world.obstacles) {
    pathPolygon(poly, true);
    ctx.fillStyle = "rgba(240,160,32,0.55)"; ctx.fill();
    ctx.strokeStyle = "#f0a020"; ctx.lineWidth = 1.5; ctx.stroke();
  }
  drawGrid(w, h);
  const f = S.frame;
  if (!f) return;

  S.drawn = { detected: 0, people: 0, tracked: 0 };
  drawDetected(f);

  // Parking boundaries of active park groups.
  for (const g of f.groups || []) {
    pathPolygon(g.boundary, true);
    ctx.setLineDash([8, 5]); ctx.strokeStyle = "#29d3e0"; ctx.lineWidth = 2; ctx.stroke(); ctx.setLineDash([]);
    ctx.fillStyle = "rgba(41,211,224,0.07)"; ctx.fill();
  }

  // Planned paths (green, as in the paper's Fig. 3) and goals of skids still on their way.
  const states = f.robots.map((r) => stateName(r[3]));
  (f.paths || []).forEach((p, i) => {
    if (!p || !["moving", "stuck", "stopped", "estopped"].includes(states[i])) return;
    pathPolygon(remainingPath(p, f.robots[i]), false);
    ctx.strokeStyle = PATH_COLOUR; ctx.lineWidth = 1.5; ctx.globalAlpha = 0.8; ctx.stroke(); ctx.globalAlpha = 1;
  });
  (f.goals || []).forEach((g, i) => {
    if (!g || states[i] === "parked") return;
    drawFootprint(i, g[0], g[1], g[2], null, STATE_COLOURS[states[i]] || "#ccc", 1.2, [4, 3]);
  });

  // Skids: footprint coloured by state, heading arrow, id (labels never overlap: a label
  // with no free place is left out; the table and a hover still name the skid).
  const placed = [];
  const free = (x, y, w2, h2) => !placed.some(([a, b, c, d]) => x - w2 < c && x + w2 > a && y - h2 < d && y + h2 > b);
  f.robots.forEach((r, i) => {
    const [x, y, hd] = r;
    const selected = S.selection.has(S.world.robots[i].id);
    drawFootprint(i, x, y, hd, STATE_COLOURS[states[i]] || "#888", selected ? "#ffe14d" : "#0b0d10", selected ? 3 : 1);
    const [cx, cy] = centre(i, x, y, hd);
    const len = Math.max(8, S.world.robots[i].length_m * 0.45 * S.view.scale);
    drawArrow(cx, cy, hd, len, "rgba(0,0,0,0.75)", 2);
    const [sx, sy] = toScreen(cx, cy);
    ctx.font = "bold 12px system-ui, sans-serif";
    ctx.textAlign = "center"; ctx.textBaseline = "middle";
    ctx.lineWidth = 3; ctx.strokeStyle = "rgba(0,0,0,0.8)";
    const label = S.world.robots[i].id;
    const off = S.world.robots[i].width_m * 0.5 * S.view.scale + 9;
    const w2 = ctx.measureText(label).width / 2 + 2, h2 = 8;
    const spot = [[sx, sy - off], [sx, sy + off], [sx, sy]].find(([x, y]) => free(x, y, w2, h2));
    if (!spot) return;
    placed.push([spot[0] - w2, spot[1] - h2, spot[0] + w2, spot[1] + h2]);
    ctx.strokeText(label, spot[0], spot[1]); ctx.fillStyle = "#fff"; ctx.fillText(label, spot[0], spot[1]);
  });

  // People (moving obstacles), then the people the fleet tracks with their velocity (the
  // arrow is where the person will be in one second).
  (f.people || []).forEach(([x, y], k) => {
    const rad_m = S.world.people[k] ? S.world.people[k].radius_m : 0.3;
    const [sx, sy] = toScreen(x, y);
    ctx.beginPath(); ctx.arc(sx, sy, rad_m * S.view.scale, 0, 2 * Math.PI);
    ctx.fillStyle = "rgba(255,90,60,0.6)"; ctx.fill(); ctx.strokeStyle = "#ff5a3c"; ctx.lineWidth = 2; ctx.stroke();
    S.drawn.people++;
  });
  (f.tracked || []).forEach(([x, y, vx, vy]) => {
    const [sx, sy] = toScreen(x, y);
    ctx.beginPath(); ctx.arc(sx, sy, Math.max(3, 0.12 * S.view.scale), 0, 2 * Math.PI);
    ctx.strokeStyle = TRACKED_COLOUR; ctx.lineWidth = 2; ctx.stroke();
    const speed = Math.hypot(vx, vy);
    if (speed > 0.02) drawArrow(x, y, deg(Math.atan2(vy, vx)), Math.max(10, speed * S.view.scale), TRACKED_COLOUR, 2);
    S.drawn.tracked++;
  });

  drawOperatorLayer();
  drawScaleAndLegend(w, h);
}

function drawDetected(f) {
  // Obstacles the skids' scans detected (onboard sensing): the squares holding them.
  const d = f.detected, side = S.world.detection_square_m;
  if (!d || !side || !d.squares.length) return;
  const px = Math.max(1, side * S.view.scale);
  ctx.fillStyle = "rgba(208,64,255,0.75)";
  for (let k = 0; k + 1 < d.squares.length; k += 2) {
    const [sx, sy] = toScreen(d.squares[k] * side, (d.squares[k + 1] + 1) * side);
    ctx.fillRect(sx, sy, px, px);
  }
  S.drawn.detected = d.squares.length / 2;
}

function drawScaleAndLegend(w, h) {
  // Scale bar: a round length (1, 2 or 5 x 10^k m) about 100 px long.
  const target = 100 / S.view.scale;
  const p = Math.pow(10, Math.floor(Math.log10(target)));
  const len = [1, 2, 5, 10].map((k) => k * p).find((v) => v >= target) || p;
  const px = len * S.view.scale, x0 = 10, y0 = h - 28;
  ctx.fillStyle = "rgba(0,0,0,0.55)"; ctx.fillRect(x0 - 4, y0 - 14, px + 8, 22);
  ctx.strokeStyle = "#fff"; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(x0, y0 - 4); ctx.lineTo(x0, y0); ctx.lineTo(x0 + px, y0); ctx.lineTo(x0 + px, y0 - 4); ctx.stroke();
  ctx.fillStyle = "#fff"; ctx.font = "11px system-ui, sans-serif"; ctx.textAlign = "center"; ctx.textBaseline = "bottom";
  ctx.fillText(`${len >= 1 ? len : len.toFixed(2)} m`, x0 + px / 2, y0 - 2);
  // Legend: the state colours, then people and obstacles.
  const items = [...Object.entries(STATE_COLOURS), ["person", "#ff5a3c"], ["obstacle", "#f0a020"], ["preview", "#ff78ff"]];
  if (S.world.sensing) items.push(["detected", DETECTED_COLOUR]);
  if (S.frame && S.frame.tracked) items.push(["tracked, v", TRACKED_COLOUR]);
  ctx.font = "11px system-ui, sans-serif"; ctx.textAlign = "left"; ctx.textBaseline = "middle";
  const lw = 84, lx = w - lw - 8;
  let ly = 10;
  ctx.fillStyle = "rgba(0,0,0,0.55)"; ctx.fillRect(lx - 4, ly - 4, lw + 4, items.length * 14 + 6);
  for (const [name, colour] of items) {
    ctx.fillStyle = colour; ctx.fillRect(lx, ly + 2, 9, 9);
    ctx.fillStyle = "#ddd"; ctx.fillText(name, lx + 14, ly + 7);
    ly += 14;
  }
}

function remainingPath(flat, robot) {
  // The path as planned starts where the skid was; draw what is left of it: from the skid
  // to the end of the nearest segment, then on.
  const pts = [];
  for (let k = 0; k + 1 < flat.length; k += 2) pts.push([flat[k], flat[k + 1]]);
  if (pts.length < 2) return pts;
  const [x, y] = robot;
  let best = 0, bestD = Infinity;
  for (let k = 0; k + 1 < pts.length; k++) {
    const [ax, ay] = pts[k], [bx, by] = pts[k + 1];
    const dx = bx - ax, dy = by - ay, L2 = dx * dx + dy * dy || 1e-12;
    const u = Math.max(0, Math.min(1, ((x - ax) * dx + (y - ay) * dy) / L2));
    const d = Math.hypot(ax + u * dx - x, ay + u * dy - y);
    if (d < bestD) { bestD = d; best = k; }
  }
  return [[x, y], ...pts.slice(best + 1)];
}

function drawGrid(w, h) {
  // A 1 m / 5 m grid when zoomed in enough to be useful.
  if (S.view.scale < 12) return;
  const [x0, y1] = toWorld(0, 0), [x1, y0] = toWorld(w, h);
  ctx.lineWidth = 1;
  for (let x = Math.floor(x0); x <= x1; x++) {
    const [sx] = toScreen(x, 0);
    ctx.strokeStyle = x % 5 === 0 ? "rgba(60,120,200,0.28)" : "rgba(60,120,200,0.12)";
    ctx.beginPath(); ctx.moveTo(sx, 0); ctx.lineTo(sx, h); ctx.stroke();
  }
  for (let y = Math.floor(y0); y <= y1; y++) {
    const [, sy] = toScreen(0, y);
    ctx.strokeStyle = y % 5 === 0 ? "rgba(60,120,200,0.28)" : "rgba(60,120,200,0.12)";
    ctx.beginPath(); ctx.moveTo(0, sy); ctx.lineTo(w, sy); ctx.stroke();
  }
}

function drawOperatorLayer() {
  const d = S.drawing;
  // The boundary being drawn or awaiting confirmation, and the previewed goals.
  if (S.boundary) {
    pathPolygon(S.boundary, true);
    ctx.fillStyle = "rgba(255,225,77,0.10)"; ctx.fill();
    ctx.strokeStyle = "#ffe14d"; ctx.lineWidth = 2; ctx.stroke();
  }
  if (S.preview && S.preview.goals) {
    const order = S.preview.robots.map((id) => ids().indexOf(id));
    const goalOf = S.preview.goal_of || [];
    const robotOfGoal = new Map(goalOf.map((g, k) => [g, order[k]]));
    const rank = new Map((S.preview.fill_order || []).map((g, k) => [g, k + 1]));
    // Spots no manoeuvre reaches in fill order (plan/spot_reach): drawn red.
    const stuck = new Set(((S.preview.report || {}).unreachable_spots || []).map((u) => u.spot));
    S.preview.goals.forEach((g, k) => {
      const i = robotOfGoal.has(k) ? robotOfGoal.get(k) : (order[k] >= 0 ? order[k] : 0);
      if (stuck.has(k)) drawFootprint(i, g[0], g[1], g[2], "rgba(255,60,60,0.35)", "#ff3c3c", 2, [5, 3]);
      else drawFootprint(i, g[0], g[1], g[2], "rgba(255,120,255,0.18)", "#ff78ff", 1.5, [5, 3]);
      const [cx, cy] = centre(i, g[0], g[1], g[2]);
      drawArrow(cx, cy, g[2], Math.max(6, 0.4 * S.view.scale), "#ff78ff", 1.5);
      if (rank.has(k)) {  // the fill order: 1 is parked first
        const [sx, sy] = toScreen(cx, cy);
        ctx.font = "bold 12px system-ui, sans-serif"; ctx.textAlign = "center"; ctx.textBaseline = "middle";
        ctx.lineWidth = 3; ctx.strokeStyle = "#000"; ctx.strokeText(String(rank.get(k)), sx, sy);
        ctx.fillStyle = "#ff78ff"; ctx.fillText(String(rank.get(k)), sx, sy);
      }
    });
    // Which skid goes to which spot.
    if (S.frame) {
      ctx.setLineDash([3, 4]); ctx.strokeStyle = "rgba(255,120,255,0.7)"; ctx.lineWidth = 1.2;
      goalOf.forEach((gk, k) => {
        const i = order[k], r = S.frame.robots[i], g = S.preview.goals[gk];
        if (i < 0 || !r || !g) return;
        const [ax, ay] = toScreen(r[0], r[1]), [bx, by] = toScreen(g[0], g[1]);
        ctx.beginPath(); ctx.moveTo(ax, ay); ctx.lineTo(bx, by); ctx.stroke();
      });
      ctx.setLineDash([]);
    }
  }
  if (!d) return;
  if (d.kind === "polygon" && d.pts.length) {
    const pts = S.mouse ? [...d.pts, S.mouse] : d.pts;
    pathPolygon(pts, false);
    ctx.strokeStyle = "#ffe14d"; ctx.lineWidth = 2; ctx.setLineDash([6, 4]); ctx.stroke(); ctx.setLineDash([]);
    d.pts.forEach(([x, y]) => {
      const [sx, sy] = toScreen(x, y);
      ctx.fillStyle = "#ffe14d"; ctx.fillRect(sx - 3, sy - 3, 6, 6);
    });
  } else if ((d.kind === "rect" || d.kind === "box") && d.end) {
    const [ax, ay] = toScreen(...d.start), [bx, by] = toScreen(...d.end);
    ctx.setLineDash([6, 4]);
    ctx.strokeStyle = d.kind === "box" ? "#ffffff" : "#ffe14d"; ctx.lineWidth = 1.5;
    ctx.strokeRect(Math.min(ax, bx), Math.min(ay, by), Math.abs(bx - ax), Math.abs(by - ay));
    ctx.setLineDash([]);
  } else if (d.kind === "goal") {
    const i = d.robot;
    drawFootprint(i, d.start[0], d.start[1], d.heading, "rgba(255,225,77,0.2)", "#ffe14d", 2, [5, 3]);
    drawArrow(d.start[0], d.start[1], d.heading, Math.max(14, 0.8 * S.view.scale), "#ffe14d", 2);
  }
}

function renderLoop() {
  if (S.dirty) { S.dirty = false; draw(); }
  pollGamepad();
  requestAnimationFrame(renderLoop);
}

// ------------------------------------------------------------------ panels

function updatePanels() {
  const f = S.frame;
  if (!f || !S.world) return;
  $("sim-time").textContent = f.t_s.toFixed(1);
  const sim = f.sim || {};
  $("sim-pause").textContent = sim.paused ? "Run" : "Pause";
  $("sim-speed").textContent = (sim.speed >= 1 ? sim.speed.toFixed(sim.speed % 1 ? 1 : 0) : sim.speed.toFixed(2)) + "x";
  $("sim-speed").title = "achieved " + (sim.rate ?? 0) + " sim s per s; tick " + (sim.tick_ms ?? "-") + " ms";
  $("estop").classList.toggle("latched", !!f.estop);
  $("estop-banner").classList.toggle("hidden", !f.estop);
  if (S.estopSent && S.estopSent.state !== "applied" && f.estop && f.robots.every((r) => r[4] === 0)) {
    S.estopSent.state = "applied";
    S.estopSent.appliedMs = Math.round(performance.now() - S.estopSent.at);
    showEstopState();
  } else if (!f.estop && S.estopSent && S.estopSent.state === "applied") {
    S.estopSent = null; showEstopState();
  }
  $("sim-speed").textContent += ` (${(sim.rate ?? 0).toFixed(2)}x)`;
  const alarms = f.alarms || [];
  $("alarm-count").textContent = alarms.length ? `(${alarms.length})` : "(none)";
  $("alarms").innerHTML = "";
  for (const a of [...alarms].reverse()) {
    const li = document.createElement("li");
    li.textContent = `${a.t_s.toFixed(1)} s  ${a.kind}${a.robots ? " " + a.robots.join(", ") : ""}: ${a.text}`;
    $("alarms").appendChild(li);
  }
  $("error-banner").classList.toggle("hidden", !sim.error);
  $("error-banner").textContent = sim.error || "";

  // Per-skid table: rebuilt in place (100 rows at 20 Hz is cheap).
  const tbody = $("status-table").tBodies[0];
  const rows = f.robots;
  while (tbody.rows.length < rows.length) {
    const tr = tbody.insertRow();
    for (let k = 0; k < 4; k++) tr.insertCell();
    tr.addEventListener("click", (ev) => selectRobot(tr.dataset.robot, ev.shiftKey));
  }
  while (tbody.rows.length > rows.length) tbody.deleteRow(-1);
  rows.forEach((r, i) => {
    const id = S.world.robots[i].id, st = stateName(r[3]);
    const tr = tbody.rows[i];
    tr.dataset.robot = id; tr.dataset.state = st;
    tr.classList.toggle("sel", S.selection.has(id));
    tr.cells[0].textContent = id;
    tr.cells[1].innerHTML = `<span class="chip" style="background:${STATE_COLOURS[st] || "#888"}"></span>${st}`;
    tr.cells[2].textContent = r[4].toFixed(2);
    const g = f.goals && f.goals[i];
    tr.cells[3].textContent = g ? `${g[0].toFixed(1)}, ${g[1].toFixed(1)}, ${g[2].toFixed(0)}°` : "-";
  });

  updateRobotPanel();

  if (f.metrics) {
    const m = f.metrics;
    const fmt = (v, d = 2) => (v === null || v === undefined ? "-" : typeof v === "number" ? v.toFixed(d) : String(v));
    $("metrics").innerHTML = [
      ["parked", `${m.parked} / ${m.commanded}`],
      ["success", String(m.success)],
      ["time to park", fmt(m.time_to_park_s, 1) + " s (bound " + fmt(m.lower_bound_s, 1) + " s)"],
      ["collisions", m.collisions],
      ["min clearance", fmt(m.min_clearance_m, 3) + " m"],
      ["deadlocks", m.deadlocks],
      ["path length", fmt(m.path_length_m, 1) + " m"],
    ].map(([k, v]) => `<div><span>${k}</span><span>${v}</span></div>`).join("");
  }
  if (f.log && f.log !== updatePanels.lastLog) {
    updatePanels.lastLog = f.log;
    $("log").innerHTML = "";
    for (const o of [...f.log].reverse()) {
      const li = document.createElement("li");
      li.className = o.accepted ? "ok" : "refused";
      const who = o.robots ? " " + o.robots.join(", ") + (o.n > o.robots.length ? ` +${o.n - o.robots.length}` : "") : "";
      li.textContent = `${o.t_s.toFixed(1)} s  ${o.command}${o.robot ? " " + o.robot : ""}${who}: ` +
        (o.accepted ? "accepted" : "refused: " + o.reason);
      $("log").appendChild(li);
    }
  }
}

// The per-skid panel: the one selected skid (a click on it) in detail.
function updateRobotPanel() {
  const f = S.frame, sel = [...S.selection];
  const i = sel.length === 1 ? ids().indexOf(sel[0]) : -1;
  $("robot-box").classList.toggle("hidden", i < 0 || !f);
  if (i < 0 || !f) return;
  const r = f.robots[i], info = f.robot_info || {}, g = f.goals && f.goals[i];
  const order = f.orders && f.orders[i], cmd = info.cmd && info.cmd[i];
  const err = info.loc_err_m ? info.loc_err_m[i] : null;
  const set = (id, text) => { $(id).textContent = text; };
  set("rp-id", sel[0]);
  set("rp-state", stateName(r[3]));
  set("rp-speed", r[4].toFixed(2) + " m/s");
  set("rp-goal", g ? `${g[0].toFixed(2)}, ${g[1].toFixed(2)}, ${g[2].toFixed(0)}°` : "none");
  set("rp-loc", S.world.sensing ? (err === null || err === undefined ? "-" : (100 * err).toFixed(1) + " cm")
    : "not localizing onboard");
  set("rp-cmd", cmd ? `v ${cmd[0].toFixed(2)} m/s, ω ${cmd[1].toFixed(2)} rad/s` : "-");
  set("rp-order", order ? `${order[0]} at ${order[1].toFixed(1)} s` : "none");
}

function updateSelectionPanel() {
  const sel = [...S.selection];
  $("sel-count").textContent = sel.length ? `(${sel.length})` : "(none)";
  $("sel-list").textContent = sel.join(" ");
  const can = S.control;
  $("btn-stop").disabled = !can || !sel.length;
  $("btn-resume").disabled = !can || !sel.length;
  $("btn-teleop").disabled = !can || sel.length !== 1 || S.teleop.robot === sel[0];
  $("btn-release").disabled = !can || !S.teleop.robot;
  updateParkPanel();
  updateRobotPanel();
  S.dirty = true;
}

function updateParkPanel() {
  const st = $("park-status");
  st.classList.remove("bad");
  const ready = S.boundary && S.selection.size && S.preview && S.preview.goals;
  $("park-confirm").disabled = !S.control || !ready;
  if (!S.selection.size) st.textContent = "Select skids, then draw a boundary.";
  else if (!S.boundary) st.textContent = `${S.selection.size} skid(s) selected: draw the parking boundary.`;
  else if (!S.preview) st.textContent = "Computing the layout...";
  else if (S.preview.error) { st.textContent = S.preview.error; st.classList.add("bad"); }
  else {
    const stuck = S.preview.report.unreachable_spots || [];
    st.textContent = `Preview: ${S.preview.goals.length} goals (${S.preview.method}, heading ` +
      `${S.preview.report.heading_deg ?? "?"}°, spacing ${(S.preview.report.min_spacing_m ?? 0).toFixed(2)} m). ` +
      (stuck.length ? `${stuck.length} spot(s) in red: ${stuck[0].reason}. ` : "") + "Confirm to park.";
    if (stuck.length) st.classList.add("bad");
  }
}

function setTool(tool) {
  S.tool = tool;
  S.drawing = null;
  document.querySelectorAll(".tool").forEach((b) => b.classList.toggle("active", b.dataset.tool === tool));
  const hints = {
    select: "",
    polygon: "Boundary: click the vertices, double-click (or click the first vertex) to close. Esc cancels.",
    rect: "Rectangle: drag the parking boundary. Esc cancels.",
    goal: "Goal: click the goal of the selected skid, drag to set its heading.",
  };
  $("hint").textContent = hints[tool] || "";
  S.dirty = true;
}

function selectRobot(id, add) {
  if (add) { if (S.selection.has(id)) S.selection.delete(id); else S.selection.add(id); }
  else S.selection = new Set([id]);
  selectionChanged();
}

function selectionChanged() {
  // Keep the world's order so a park command lists skids the same way every time.
  S.selection = new Set(ids().filter((id) => S.selection.has(id)));
  updateSelectionPanel();
  requestPreview();
}

// ------------------------------------------------------------------ park

function parkBody() {
  const body = {
    robots: [...S.selection],
    boundary: S.boundary.map(([x, y]) => [+x.toFixed(3), +y.toFixed(3)]),
    method: $("park-method").value,
    margin_m: parseFloat($("park-margin").value) || 0,
    assignment: $("park-assign").value,
  };
  body.heading_deg = $("park-auto").checked ? "auto" : parseFloat($("park-heading").value) || 0;
  return body;
}

function requestPreview() {
  S.preview = null;
  updateParkPanel();
  S.dirty = true;
  if (!S.boundary || !S.selection.size || !S.control) return;
  clearTimeout(requestPreview.timer);
  requestPreview.timer = setTimeout(async () => {
    const seq = ++S.previewSeq;
    const r = await api("/api/park/preview", parkBody());
    if (seq !== S.previewSeq) return;   // a newer request is on its way
    S.preview = r.ok ? r.data : { error: why(r) };
    updateParkPanel();
    S.dirty = true;
  }, 120);
}

async function confirmPark() {
  if (!S.boundary || !S.selection.size) return;
  const r = await command("/api/park", parkBody(), "park command accepted");
  if (r.ok) { S.boundary = null; S.preview = null; setTool("select"); updateParkPanel(); }
}

function clearBoundary() {
  S.boundary = null; S.preview = null; S.drawing = null;
  updateParkPanel(); S.dirty = true;
}

function closePolygon(pts) {
  // Drop repeated vertices (a double-click adds the same point twice).
  const out = [];
  for (const p of pts) {
    const q = out[out.length - 1];
    if (!q || Math.hypot(p[0] - q[0], p[1] - q[1]) * S.view.scale > 3) out.push(p);
  }
  if (out.length >= 3) {
    const a = out[0], b = out[out.length - 1];
    if (Math.hypot(a[0] - b[0], a[1] - b[1]) * S.view.scale <= 3) out.pop();
  }
  if (out.length < 3) { toast("a boundary needs at least 3 vertices"); return; }
  S.boundary = out;
  S.drawing = null;
  setTool("select");
  requestPreview();
}

// ------------------------------------------------------------------ mouse

canvas.addEventListener("contextmenu", (ev) => ev.preventDefault());

canvas.addEventListener("mousedown", (ev) => {
  canvas.focus();
  const [px, py] = eventXY(ev);
  const wpt = toWorld(px, py);
  if (ev.button === 1 || ev.button === 2) {
    S.pan = { px, py, cx: S.view.cx, cy: S.view.cy };
    ev.preventDefault();
    return;
  }
  if (ev.button !== 0 || !S.world) return;
  if (S.tool === "select") {
    const hit = robotAt(...wpt);
    if (hit !== null) { selectRobot(S.world.robots[hit].id, ev.shiftKey); return; }
    S.drawing = { kind: "box", start: wpt, end: null, shift: ev.shiftKey };
  } else if (S.tool === "rect") {
    S.boundary = null; S.preview = null;
    S.drawing = { kind: "rect", start: wpt, end: null };
  } else if (S.tool === "polygon") {
    if (!S.drawing || S.drawing.kind !== "polygon") { S.boundary = null; S.preview = null; S.drawing = { kind: "polygon", pts: [] }; }
    const pts = S.drawing.pts;
    if (pts.length >= 3) {
      const [fx, fy] = toScreen(...pts[0]);
      if (Math.hypot(fx - px, fy - py) < 8) { closePolygon(pts); return; }
    }
    pts.push(wpt);
  } else if (S.tool === "goal") {
    if (S.selection.size !== 1) { toast("select exactly one skid for a manual goal"); return; }
    const i = ids().indexOf([...S.selection][0]);
    const cur = S.frame ? S.frame.robots[i][2] : 0;
    S.drawing = { kind: "goal", robot: i, start: wpt, startPx: [px, py], heading: cur };
  }
  S.dirty = true;
});

window.addEventListener("mousemove", (ev) => {
  const [px, py] = eventXY(ev);
  S.mouse = toWorld(px, py);
  if (S.pan) {
    S.view.cx = S.pan.cx - (px - S.pan.px) / S.view.scale;
    S.view.cy = S.pan.cy + (py - S.pan.py) / S.view.scale;
  }
  const d = S.drawing;
  if (d && (d.kind === "box" || d.kind === "rect")) d.end = S.mouse;
  if (d && d.kind === "goal") {
    const dx = px - d.startPx[0], dy = py - d.startPx[1];
    if (Math.hypot(dx, dy) > 6) d.heading = deg(Math.atan2(-dy, dx));
  }
  $("hud").textContent = `x ${S.mouse[0].toFixed(2)}  y ${S.mouse[1].toFixed(2)} m   ${S.view.scale.toFixed(0)} px/m`;
  S.dirty = true;
});

window.addEventListener("mouseup", (ev) => {
  if (S.pan && (ev.button === 1 || ev.button === 2)) { S.pan = null; return; }
  const d = S.drawing;
  if (!d || ev.button !== 0) return;
  if (d.kind === "box") {
    S.drawing = null;
    if (!d.end) { if (!d.shift) { S.selection.clear(); selectionChanged(); } return; }
    const [x0, x1] = [Math.min(d.start[0], d.end[0]), Math.max(d.start[0], d.end[0])];
    const [y0, y1] = [Math.min(d.start[1], d.end[1]), Math.max(d.start[1], d.end[1])];
    if (!d.shift) S.selection.clear();
    S.frame.robots.forEach((r, i) => {
      const [cx, cy] = centre(i, r[0], r[1], r[2]);
      if (cx >= x0 && cx <= x1 && cy >= y0 && cy <= y1) S.selection.add(S.world.robots[i].id);
    });
    selectionChanged();
  } else if (d.kind === "rect") {
    S.drawing = null;
    if (!d.end) return;
    const [x0, x1] = [Math.min(d.start[0], d.end[0]), Math.max(d.start[0], d.end[0])];
    const [y0, y1] = [Math.min(d.start[1], d.end[1]), Math.max(d.start[1], d.end[1])];
    if ((x1 - x0) * S.view.scale < 5 || (y1 - y0) * S.view.scale < 5) return;
    S.boundary = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]];
    setTool("select");
    requestPreview();
  } else if (d.kind === "goal") {
    S.drawing = null;
    const id = S.world.robots[d.robot].id;
    command("/api/goto", { robot: id, pose: [+d.start[0].toFixed(3), +d.start[1].toFixed(3), +d.heading.toFixed(1)] },
      `goal sent to ${id}`);
  }
  S.dirty = true;
});

canvas.addEventListener("dblclick", (ev) => {
  if (S.tool === "polygon" && S.drawing && S.drawing.kind === "polygon") closePolygon(S.drawing.pts);
  ev.preventDefault();
});

canvas.addEventListener("wheel", (ev) => {
  const [px, py] = eventXY(ev);
  zoomAt(px, py, Math.exp(-ev.deltaY * 0.0015));
  ev.preventDefault();
}, { passive: false });

// ------------------------------------------------------------------ keyboard

function typing(ev) {
  const t = ev.target;
  return t && (t.tagName === "INPUT" || t.tagName === "SELECT" || t.tagName === "TEXTAREA");
}

// Fields where Space is text: everywhere else Space is the e-stop.
function textEntry(ev) {
  const t = ev.target;
  if (!t) return false;
  if (t.tagName === "TEXTAREA") return true;
  return t.tagName === "INPUT" && ["text", "number", "password", "search"].includes(t.type);
}

const TELEOP_KEYS = ["ArrowUp", "ArrowDown", "ArrowLeft", "ArrowRight"];

window.addEventListener("keydown", (ev) => {
  if (ev.code === "Space" && !textEntry(ev)) {
    ev.preventDefault();
    if (!ev.repeat) estop();
    return;
  }
  if (TELEOP_KEYS.includes(ev.key) && !typing(ev)) {
    // Tracked even before a take-over completes, so a key already held counts.
    S.teleop.keys.add(ev.key);
    if (S.teleop.robot) { ev.preventDefault(); return; }
  }
  if (typing(ev)) return;
  const k = ev.key.toLowerCase();
  if (ev.key === "Escape") { S.drawing = null; if (S.tool !== "select") setTool("select"); else clearBoundary(); }
  else if (ev.key === "Enter" && S.drawing && S.drawing.kind === "polygon") closePolygon(S.drawing.pts);
  else if (k === "s") setTool("select");
  else if (k === "b") setTool("polygon");
  else if (k === "r") setTool("rect");
  else if (k === "g") setTool("goal");
  else if (k === "f") fit();
  else if (k === "p") togglePause();
  else if (ev.key === "+" || ev.key === "=") setSpeed(2);
  else if (ev.key === "-") setSpeed(0.5);
  S.dirty = true;
});

window.addEventListener("keyup", (ev) => {
  S.teleop.keys.delete(ev.key);
  // A focused button would also "click" on Space's keyup: the e-stop key does nothing else.
  if (ev.code === "Space" && !textEntry(ev)) ev.preventDefault();
});
window.addEventListener("blur", () => S.teleop.keys.clear());

// ------------------------------------------------------------------ commands

async function estop() {
  // No token needed: any console may stop the swarm.
  S.estopSent = { at: performance.now(), state: "sent" };
  showEstopState();
  const r = await api("/api/estop", undefined);
  if (!r.ok) { S.estopSent.state = "failed"; toast("E-STOP FAILED: " + why(r)); }
  else if (S.estopSent.state === "sent") S.estopSent.state = "acknowledged";
  showEstopState();
}

// Sent -> acknowledged (the server answered) -> applied (a frame shows every skid halted).
function showEstopState() {
  const e = S.estopSent, el = $("estop-state");
  if (!e) { el.textContent = ""; return; }
  const ms = Math.round(performance.now() - e.at);
  el.textContent = { sent: "sent…", acknowledged: "acknowledged", applied: "applied: all halted", failed: "NOT SENT" }[e.state]
    + (e.state === "applied" ? ` (${e.appliedMs} ms)` : "");
  el.className = e.state;
  if (e.state === "sent" && ms > 1000) el.textContent = "sent, no answer yet…";
}

async function togglePause() {
  const paused = S.frame && S.frame.sim ? S.frame.sim.paused : false;
  await command("/api/sim", { paused: !paused });
}

async function setSpeed(factor) {
  const cur = S.frame && S.frame.sim ? S.frame.sim.speed : 1;
  const lim = S.meta ? S.meta.limits.sim_speed : { min: null, max: null };
  let speed = +(cur * factor).toPrecision(3);
  if (lim.max !== null) speed = Math.min(lim.max, speed);
  if (lim.min !== null) speed = Math.max(lim.min, speed);
  await command("/api/sim", { speed });
}

// ------------------------------------------------------------------ teleop

function gamepad() {
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  for (const p of pads) if (p && p.connected) return p;
  return null;
}

function pollGamepad() {
  const p = gamepad();
  $("gamepad").textContent = p ? p.id.slice(0, 28) : "no gamepad";
}

function teleopCommand() {
  const i = ids().indexOf(S.teleop.robot);
  const spec = S.world.robots[i];
  const scale = parseFloat($("teleop-scale").value);
  let fwd = 0, turn = 0;
  const keys = S.teleop.keys;
  if (keys.has("ArrowUp")) fwd += 1;
  if (keys.has("ArrowDown")) fwd -= 1;
  if (keys.has("ArrowLeft")) turn += 1;
  if (keys.has("ArrowRight")) turn -= 1;
  const p = gamepad();
  if (p && fwd === 0 && turn === 0) {
    // Left stick: up drives forward (axis 1 is negative up), left turns counter-clockwise.
    const dz = (v) => (Math.abs(v) < GAMEPAD_DEADZONE ? 0 : v);
    fwd = -dz(p.axes[1] || 0);
    turn = -dz(p.axes[0] || 0);
  }
  return [fwd * scale * spec.max_speed_mps, turn * scale * spec.max_yaw_rate_radps];
}

async function takeOver() {
  if (S.selection.size !== 1 || !S.meta) return;
  const robot = [...S.selection][0];
  const r = await command("/api/teleop", { robot, v_mps: 0, omega_radps: 0 });
  if (!r.ok) return;
  S.teleop.robot = robot;
  $("teleop-robot").textContent = robot;
  $("teleop-box").classList.remove("hidden");
  clearInterval(S.teleop.timer);
  // Keep sending while driving: the server stops the skid if the commands stop coming.
  S.teleop.timer = setInterval(async () => {
    if (!S.teleop.robot || document.hidden) return;
    const [v, w] = teleopCommand();
    S.teleop.last = [v, w];
    $("teleop-cmd").textContent = `v ${v.toFixed(2)} m/s  ω ${deg(w).toFixed(0)}°/s`;
    const res = await api("/api/teleop", { robot: S.teleop.robot, v_mps: v, omega_radps: w });
    if (!res.ok && S.teleop.robot) { toast(why(res)); stopTeleop(); }
  }, S.meta.limits.teleop.send_period_s * 1000);
  updateSelectionPanel();
}

function stopTeleop() {
  clearInterval(S.teleop.timer);
  S.teleop.robot = null;
  S.teleop.keys.clear();
  $("teleop-box").classList.add("hidden");
  updateSelectionPanel();
}

async function release() {
  const robot = S.teleop.robot;
  if (!robot) return;
  stopTeleop();
  await command("/api/release", { robot }, `${robot} handed back to autonomy`);
}

// ------------------------------------------------------------------ buttons

$("estop").addEventListener("click", estop);
$("resume-all").addEventListener("click", () => command("/api/resume", { robots: "all" }));
$("btn-stop").addEventListener("click", () => command("/api/stop", { robots: [...S.selection] }));
$("btn-resume").addEventListener("click", () => command("/api/resume", { robots: [...S.selection] }));
$("btn-teleop").addEventListener("click", takeOver);
$("btn-release").addEventListener("click", release);
$("park-confirm").addEventListener("click", confirmPark);
$("park-cancel").addEventListener("click", clearBoundary);
for (const id of ["park-method", "park-heading", "park-margin", "park-assign", "park-auto"]) {
  $(id).addEventListener("change", requestPreview);
}
document.querySelectorAll(".tool").forEach((b) => b.addEventListener("click", () => setTool(b.dataset.tool)));
$("sim-pause").addEventListener("click", togglePause);
$("sim-faster").addEventListener("click", () => setSpeed(2));
$("sim-slower").addEventListener("click", () => setSpeed(0.5));
$("sim-reset").addEventListener("click", () => command("/api/sim/reset", {}, "scenario reset"));
$("scenario-load").addEventListener("click", async () => {
  const r = await command("/api/scenario", { name: $("scenario-select").value, scripted: $("scenario-scripted").checked },
    "scenario loaded");
  if (r.ok) { S.selection.clear(); clearBoundary(); stopTeleop(); }
});
$("zoom-in").addEventListener("click", () => { const [w, h] = cssSize(); zoomAt(w / 2, h / 2, 1.4); });
$("zoom-out").addEventListener("click", () => { const [w, h] = cssSize(); zoomAt(w / 2, h / 2, 1 / 1.4); });
$("zoom-fit").addEventListener("click", fit);
$("token-apply").addEventListener("click", () => {
  S.token = $("token-input").value.trim();
  sessionStorage.setItem("swarmpark-token", S.token);
  checkAuth();
});

// ------------------------------------------------------------------ server state

async function checkAuth() {
  const r = await api("/api/auth", undefined, "GET");
  if (!r.ok) return;
  S.tokenRequired = r.data.token_required;
  S.secretRequired = !!r.data.secret_required;
  S.control = r.data.control;
  $("auth").classList.toggle("hidden", !S.tokenRequired);
  // Say why this viewer is read-only (the e-stop still works).
  let why_ro = "";
  if (!S.control && S.tokenRequired) why_ro = S.token ? "the token was refused: read-only (E-STOP still works)" : "read-only: enter the token to command (E-STOP still works)";
  else if (!S.control && S.secretRequired) why_ro = S.secret ? "the server's secret was refused: read-only (E-STOP still works)" : "read-only: open the URL that swarmpark serve printed to command (E-STOP still works)";
  $("ro-banner").textContent = why_ro;
  $("ro-banner").classList.toggle("hidden", !why_ro);
  $("auth-badge").textContent = S.control ? "control" : "read-only";
  $("auth-badge").className = "badge " + (S.control ? "" : "warn");
  document.querySelectorAll("button.ctl, select, input").forEach((el) => {
    if (!el.closest("#auth")) el.disabled = !S.control;
  });
  updateSelectionPanel();
}

// The choices and limits come from the server (its registries and request schemas).
function fillSelect(sel, choices, chosen) {
  const keep = sel.value;
  sel.replaceChildren(...choices.map((c) => {
    const o = document.createElement("option");
    o.value = c.name;
    o.textContent = c.name;
    o.title = c.description;
    return o;
  }));
  sel.value = choices.some((c) => c.name === keep) ? keep : chosen;
}

function setRange(input, range) {
  for (const k of ["min", "max", "step"]) {
    if (range[k] === null || range[k] === undefined) input.removeAttribute(k);
    else input.setAttribute(k, range[k]);
  }
}

async function loadMeta() {
  const r = await api("/api/meta", undefined, "GET");
  if (!r.ok) { toast("cannot read the methods and limits: " + why(r)); return; }
  const first = !S.meta;
  S.meta = r.data;
  fillSelect($("park-method"), r.data.layout_methods, r.data.defaults.method);
  fillSelect($("park-assign"), r.data.assignment_costs, r.data.defaults.assignment);
  const lim = r.data.limits;
  setRange($("park-margin"), lim.margin_m);
  setRange($("park-heading"), lim.heading_deg);
  $("park-auto").closest("label").classList.toggle("hidden", !lim.heading_deg.special.includes("auto"));
  if (first) {
    $("park-margin").value = lim.margin_m.default;
    $("park-heading").value = lim.heading_deg.default;
  }
}

async function loadWorld(rev) {
  const r = await api("/api/world", undefined, "GET");
  if (!r.ok) return;
  const first = !S.world || S.world.file !== r.data.file;
  S.world = r.data;
  loadMeta();  // refreshed with every scenario (robots_per_park is the fleet size)
  const img = new Image();
  img.onload = () => { S.dirty = true; };
  img.src = "/api/map?rev=" + S.world.rev;
  S.mapImg = img;
  // A reset keeps the view and the selection; another scenario starts afresh.
  if (first) { S.selection.clear(); clearBoundary(); fit(); }
  S.selection = new Set(ids().filter((id) => S.selection.has(id)));
  updateSelectionPanel();
  loadScenarios();
}

async function loadScenarios() {
  const r = await api("/api/scenarios", undefined, "GET");
  if (!r.ok) return;
  const sel = $("scenario-select");
  const names = r.data.scenarios.includes(r.data.current) ? r.data.scenarios : [r.data.current, ...r.data.scenarios];
  sel.innerHTML = names.map((n) => `<option value="${n}">${n}</option>`).join("");
  sel.value = r.data.current;
}

let loadingRev = null;

async function onFrame(msg) {
  if (msg.type !== "state") return;
  if (!S.world || S.world.rev !== msg.rev) {
    if (loadingRev !== msg.rev) {
      loadingRev = msg.rev;
      await loadWorld(msg.rev);
    }
    if (!S.world || S.world.rev !== msg.rev) return;
  }
  // Slow parts are sent only when they change: keep the last ones.
  const prev = msg.full || !S.frame || S.frame.rev !== msg.rev ? {} : S.frame;
  const f = { ...msg };
  for (const k of SLOW_KEYS) if (!(k in msg) && k in prev) f[k] = prev[k];
  S.frame = f;
  S.lastFrameAt = performance.now();
  S.frames.push({ t_s: f.t_s, estop: f.estop, robots: f.robots });
  if (S.frames.length > 400) S.frames.splice(0, S.frames.length - 400);
  updatePanels();
  S.dirty = true;
}

function connect() {
  const proto = location.protocol === "https:" ? "wss:" : "ws:";
  const ws = new WebSocket(`${proto}//${location.host}/api/ws`);
  ws.onopen = () => { $("conn").textContent = "live"; $("conn").className = "badge"; connect.delay = 500; };
  ws.onmessage = (ev) => onFrame(JSON.parse(ev.data));
  ws.onclose = () => {
    $("conn").textContent = "disconnected"; $("conn").className = "badge bad";
    connect.delay = Math.min(5000, (connect.delay || 500) * 1.5);
    setTimeout(connect, connect.delay);
  };
}

// The token or the server's secret may come in the page URL once (?token=..., ?secret=...):
// keep them for this tab, hide them.
(function takeTokenFromUrl() {
  const u = new URL(location.href);
  for (const [key, field] of [["token", "token"], ["secret", "secret"]]) {
    const t = u.searchParams.get(key);
    if (t) {
      S[field] = t;
      sessionStorage.setItem("swarmpark-" + key, t);
      u.searchParams.delete(key);
    }
  }
  history.replaceState(null, "", u.toString());
})();

// Stale link: no frame for a second means the picture is old, whatever the socket says.
const STALE_MS = 1000;
setInterval(() => {
  const age = S.lastFrameAt ? performance.now() - S.lastFrameAt : 0;
  const stale = S.lastFrameAt && age > STALE_MS;
  $("stale-banner").classList.toggle("hidden", !stale);
  if (stale) {
    $("stale-banner").textContent = `No data from the server for ${(age / 1000).toFixed(1)} s: the view is stale.`;
    $("conn").textContent = "stale"; $("conn").className = "badge bad";
  } else if ($("conn").textContent === "stale") { $("conn").textContent = "live"; $("conn").className = "badge"; }
  if (S.estopSent && S.estopSent.state === "sent") showEstopState();
}, 250);

// For end-to-end tests and debugging: the view transform and the latest state.
window.swarmpark = { S, toScreen, toWorld, fit };

window.addEventListener("resize", () => { resize(); });
resize();
setTool("select");
checkAuth();
connect();
requestAnimationFrame(renderLoop);
