// The operator page: follows the session's state (server-sent events from /events) and sends the
// operator's commands (POST /command). Plain JavaScript, no build step.
"use strict";

const page = { state: null, terrain: null, updates: 0, events: null, finished: false };
window.operatorPage = page;

const $ = (id) => document.getElementById(id);
const fmt = (x, digits, unit) => (x === null || x === undefined || !Number.isFinite(x)) ? "-" : `${x.toFixed(digits)}${unit}`;

function describeAction(a) {
  if (!a) return "none";
  const parts = [a.kind];
  if (a.swing_rad !== undefined) parts.push(`swing ${(a.swing_rad * 180 / Math.PI).toFixed(1)} deg`);
  return parts.join(", ");
}

function showState(s) {
  page.state = s;
  page.updates += 1;
  $("time").textContent = fmt(s.time_s, 1, " s");
  $("safety").textContent = s.safety;
  $("fault").textContent = s.fault || "none";
  $("fault").className = s.fault ? "fault" : "";
  $("fault-count").textContent = s.fault_count;
  $("activity").textContent = s.activity;
  $("stage").textContent = s.stage;
  $("action").textContent = describeAction(s.action);
  $("operator-state").textContent = [s.paused ? "paused" : "running", s.stopping ? "stopping after this action" : ""].filter(Boolean).join(", ");
  showValves(s.valves);
  // Digs are numbered from 1; the current dig is the one in progress (from the move to it to its dump).
  $("digs-done").textContent = s.digs_done;
  $("current-dig").textContent = s.current_dig === null ? "none (between digs)" : `dig ${s.current_dig}`;
  const d = s.last_dig;
  $("last-dig").textContent = d ? `dig ${d.number} (${d.action})` : "-";
  $("last-weight").textContent = d ? fmt(d.weight_n === null ? null : d.weight_n / 1000, 2, " kN") : "-";
  $("last-time").textContent = d ? fmt(d.time_s, 1, " s") : "-";
  $("last-energy").textContent = d ? fmt(d.energy_kj, 1, " kJ") : "-";
  $("last-volume").textContent = d ? fmt(d.swept_volume_m3, 2, " m³") : "-";
  $("log").textContent = s.log.join("\n");
  for (const b of document.querySelectorAll("button[data-cmd]")) b.disabled = !s.operator || !!s.session_over;
  if (s.session_over) finish(s.session_over);
  draw();
}

// The valve commands as the protocol names the valves, in % of full port flow with a bar.
function showValves(valves) {
  const table = $("valves");
  if (table.rows.length !== valves.length) {
    table.replaceChildren();
    for (const v of valves) {
      const row = table.insertRow();
      row.insertCell().textContent = v.name;
      row.cells[0].className = "name";
      row.insertCell().className = "pct";
      const bar = document.createElement("span");
      bar.className = "bar";
      bar.appendChild(document.createElement("i"));
      row.insertCell().appendChild(bar);
    }
  }
  valves.forEach((v, k) => {
    const row = table.rows[k];
    const pct = v.command_pct;
    row.cells[1].textContent = pct === null ? "position mode" : `${pct >= 0 ? "+" : ""}${pct.toFixed(1)} %`;
    const fill = row.cells[2].querySelector("i");
    const f = pct === null ? 0 : Math.max(-100, Math.min(100, pct)) / 100;
    fill.style.left = `${50 + Math.min(0, f) * 50}%`;
    fill.style.width = `${Math.abs(f) * 50}%`;
  });
}

// The session ended: the page keeps its last state and says why (the server goes away with the
// session, so the event stream is closed rather than retried).
function finish(reason) {
  page.finished = true;
  if (page.events) page.events.close();
  $("session-over").hidden = false;
  $("session-over").textContent = `session finished: ${reason}`;
  $("connection").textContent = "stream closed";
  $("connection").className = "badge over";
}

// Terrain colours: low blue, high brown; unknown cells dark.
function colour(z, lo, hi) {
  const t = hi > lo ? Math.min(1, Math.max(0, (z - lo) / (hi - lo))) : 0.5;
  const r = Math.round(40 + 150 * t), g = Math.round(70 + 80 * t), b = Math.round(140 - 100 * t);
  return `rgb(${r},${g},${b})`;
}

// The terrain map and its legend drawn once per map (tens of thousands of cells) into an offscreen
// canvas, so that a state update, many a second, only copies it: redrawing every cell at each update
// kept the browser's main thread busy and the page stopped answering.
let layer = null;
function terrainLayer(t, canvas, legendW, scale, px, py) {
  if (layer && layer.terrain === t && layer.width === canvas.width && layer.height === canvas.height) {
    return layer.canvas;
  }
  const off = document.createElement("canvas");
  off.width = canvas.width;
  off.height = canvas.height;
  const ctx = off.getContext("2d");
  let lo = Infinity, hi = -Infinity;
  for (const z of t.z_m) {
    if (z !== null) { lo = Math.min(lo, z); hi = Math.max(hi, z); }
  }
  if (lo > hi) { lo = 0; hi = 0; }
  const [x0, y0] = t.origin_m;
  const side = Math.ceil(t.cell_m * scale);
  for (let j = 0; j < t.ny; j++) {
    for (let i = 0; i < t.nx; i++) {
      const z = t.z_m[j * t.nx + i];
      ctx.fillStyle = z === null ? "#22272d" : colour(z, lo, hi);
      ctx.fillRect(px(x0 + i * t.cell_m), py(y0 + (j + 1) * t.cell_m), side, side);
    }
  }
  drawLegend(ctx, canvas.width - legendW + 14, 20, canvas.height - 40, lo, hi);
  layer = { terrain: t, width: canvas.width, height: canvas.height, canvas: off };
  return off;
}

function draw() {
  const canvas = $("map");
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  const t = page.terrain, s = page.state;
  // The view: the terrain map's extent, or 20 m around the machine before the first map.
  let x0, y0, w, h;
  if (t) {
    [x0, y0] = t.origin_m; w = t.nx * t.cell_m; h = t.ny * t.cell_m;
  } else if (s) {
    x0 = s.pose[0] - 10; y0 = s.pose[1] - 10; w = 20; h = 20;
  } else {
    return;
  }
  // The right-hand strip holds the colour legend.
  const legendW = 90;
  const scale = Math.min((canvas.width - legendW) / w, canvas.height / h);
  // World x to the right, y up.
  const px = (x) => (x - x0) * scale;
  const py = (y) => canvas.height - (y - y0) * scale;
  if (t) {
    ctx.drawImage(terrainLayer(t, canvas, legendW, scale, px, py), 0, 0);
  }
  drawScaleBar(ctx, canvas.height, scale);
  if (!s) return;
  const dot = (p, r, c) => { ctx.beginPath(); ctx.arc(px(p[0]), py(p[1]), r, 0, 2 * Math.PI); ctx.fillStyle = c; ctx.fill(); };
  if (s.next_dig_m) {
    dot(s.next_dig_m, 8, "#3ddc84");
  }
  // The machine: a triangle along its heading.
  const [x, y, hd] = s.pose;
  const L = 2.5;
  ctx.beginPath();
  ctx.moveTo(px(x + L * Math.cos(hd)), py(y + L * Math.sin(hd)));
  ctx.lineTo(px(x + 0.8 * L * Math.cos(hd + 2.5)), py(y + 0.8 * L * Math.sin(hd + 2.5)));
  ctx.lineTo(px(x + 0.8 * L * Math.cos(hd - 2.5)), py(y + 0.8 * L * Math.sin(hd - 2.5)));
  ctx.closePath();
  ctx.fillStyle = "#f2c14e";
  ctx.fill();
  // The arm to the bucket tip.
  ctx.beginPath();
  ctx.moveTo(px(x), py(y));
  ctx.lineTo(px(s.tip_m[0]), py(s.tip_m[1]));
  ctx.strokeStyle = "#ff8c42";
  ctx.lineWidth = 3;
  ctx.stroke();
  dot(s.tip_m, 5, "#ff8c42");
}

// The height legend: the colour range spans the map's known cells, heights in m.
function drawLegend(ctx, x, y, h, lo, hi) {
  const steps = 40;
  for (let k = 0; k < steps; k++) {
    ctx.fillStyle = colour(hi - (hi - lo) * (k + 0.5) / steps, lo, hi);
    ctx.fillRect(x, y + k * h / steps, 14, Math.ceil(h / steps));
  }
  ctx.fillStyle = "#e6e6e6";
  ctx.font = "12px system-ui, sans-serif";
  ctx.textBaseline = "middle";
  for (const [z, at] of [[hi, y], [(lo + hi) / 2, y + h / 2], [lo, y + h]]) {
    ctx.fillText(`${z.toFixed(2)} m`, x + 18, at);
  }
  ctx.save();
  ctx.translate(x - 4, y + h / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.textAlign = "center";
  ctx.fillText("height z (m)", 0, 0);
  ctx.restore();
}

// A scale bar of a round length, about a fifth of the map's width.
function drawScaleBar(ctx, height, pxPerM) {
  const want = ctx.canvas.width / 5 / pxPerM;
  const len = [0.5, 1, 2, 5, 10, 20, 50, 100].find((l) => l >= want) || 100;
  const x = 12, y = height - 14, w = len * pxPerM;
  ctx.strokeStyle = "#e6e6e6";
  ctx.fillStyle = "#e6e6e6";
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(x, y - 5); ctx.lineTo(x, y); ctx.lineTo(x + w, y); ctx.lineTo(x + w, y - 5);
  ctx.stroke();
  ctx.font = "12px system-ui, sans-serif";
  ctx.textBaseline = "bottom";
  ctx.textAlign = "left";
  ctx.fillText(`${len} m`, x + w + 6, y + 4);
}

async function send(cmd) {
  $("command-result").textContent = `${cmd}: sent`;
  try {
    const r = await fetch("command", {
      method: "POST",
      // The session's token, which this server put in the page it served (live/src/access.rs).
      headers: {
        "Content-Type": "application/json",
        "X-Operator-Token": document.querySelector('meta[name="operator-token"]').content,
      },
      body: JSON.stringify({ cmd }),
    });
    const reply = await r.json();
    const st = reply.status;
    $("command-result").textContent = reply.ok
      ? `${cmd}: done (phase ${st ? st.phase : "?"}, fault ${st && st.fault ? st.fault : "none"}${st && st.paused ? ", paused" : ""})`
      : `${cmd}: refused: ${reply.error}`;
  } catch (e) {
    $("command-result").textContent = `${cmd}: failed: ${e}`;
  }
}

function connect() {
  const events = new EventSource("events");
  page.events = events;
  events.addEventListener("open", () => {
    $("connection").textContent = "live";
    $("connection").className = "badge on";
  });
  events.addEventListener("error", () => {
    if (page.finished) return;
    $("connection").textContent = "disconnected (retrying)";
    $("connection").className = "badge off";
  });
  events.addEventListener("state", (e) => showState(JSON.parse(e.data)));
  events.addEventListener("terrain", (e) => {
    page.terrain = JSON.parse(e.data);
    const t = page.terrain;
    $("terrain-info").textContent = `${t.nx} x ${t.ny} cells of ${t.cell_m} m: ${(t.nx * t.cell_m).toFixed(1)} m x ${(t.ny * t.cell_m).toFixed(1)} m from (${t.origin_m[0].toFixed(1)}, ${t.origin_m[1].toFixed(1)}) m in the world frame`;
    draw();
  });
}

for (const b of document.querySelectorAll("button[data-cmd]")) {
  b.addEventListener("click", () => send(b.dataset.cmd));
}
connect();
