// The replay page: draws one step of a finished run from /api/run (testbed/view/replay.py):
// the map, each robot with its path so far and a light ring for its communication range,
// the links of that step; the display robot's newest snapshot (its own picture, with its
// own labels) is shown beside the map, never over it. The live view (testbed/view/live.py)
// feeds the same page. No framework and no build step: this file is what the browser runs.
"use strict";
const canvas = document.getElementById("map");
const ctx = canvas.getContext("2d");
const slider = document.getElementById("slider");
const COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b",
                "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"];
let run = null, mapImg = null, linkSets = [], playing = null;
let selected = null, hops = {};  // live: the clicked robot, and each robot's next hop to it
let goals = {};  // live: each robot's newest goal
let stepNos = [];  // live: the run's step of each frame received (replay: the index is the step)
const snapImg = document.getElementById("snapshot");
const PAD = 14;  // pixels round the map: a robot on its edge is drawn whole, label and all

function scale() {
  // Pixels per metre, and the corner of the drawn area in metres (a `net up` network may
  // have robots at negative coordinates: its view sends the origin that holds them).
  const [wm, hm] = run.map_m;
  return [(canvas.width - 2 * PAD) / Math.max(wm, hm), run.origin || [0, 0]];
}

function toCanvas(x, y) {
  const [k, [x0, y0]] = scale();
  return [PAD + (x - x0) * k, PAD + (y - y0) * k];
}

function stepOf(i) { return run.live ? stepNos[i] : i; }

function showSnapshot(i) {
  // The newest display snapshot at or before the step shown, in its own panel.
  const step = stepOf(i);
  let best = null;
  for (const s of run.snapshots || []) if (s <= step && (best === null || s > best)) best = s;
  const panel = document.getElementById("display");
  panel.hidden = best === null;
  if (best === null) return;
  const src = "/display.png?step=" + best;
  if (snapImg.getAttribute("src") !== src) snapImg.setAttribute("src", src);
  document.getElementById("snapstep").textContent = "step " + best;
}

function drawnLinks(step) {
  // The links between robots drawn on the map (not the display robot's: it is not drawn).
  return [...linksAt(step)].map((key) => key.split("-").map(Number))
    .filter(([i, j]) => i <= run.robots && j <= run.robots);
}

function linksAt(step) {
  // links.csv holds changes; the set at a step is replayed from step 0 (cached per step).
  return linkSets[Math.min(step, linkSets.length - 1)] || new Set();
}

function buildLinkSets() {
  const byStep = new Map();
  for (const [s, added, i, j] of run.links) {
    if (!byStep.has(s)) byStep.set(s, []);
    byStep.get(s).push([added, i, j]);
  }
  let cur = new Set();
  linkSets = [];
  for (let s = 0; s <= run.steps; s++) {
    for (const [added, i, j] of byStep.get(s) || []) {
      const key = i + "-" + j;
      if (added) cur.add(key); else cur.delete(key);
    }
    linkSets.push(new Set(cur));
  }
}

function draw(step) {
  if (!run.positions.length) return;
  const [wm, hm] = run.map_m;
  const [k, [x0, y0]] = scale();
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (mapImg) {  // the ground truth, walls dark enough to read under everything else
    const [mx, my] = toCanvas(0, 0), [iw, ih] = run.map_img_m || run.map_m;
    ctx.globalAlpha = 0.7;
    ctx.drawImage(mapImg, mx, my, iw * k, ih * k);
    ctx.globalAlpha = 1;
  }
  showSnapshot(step);
  const [fx, fy] = toCanvas(x0, y0);
  ctx.strokeStyle = "#999";
  ctx.lineWidth = 1;
  ctx.strokeRect(fx, fy, wm * k, hm * k);
  const pos = run.positions[step];
  const at = (r) => toCanvas(pos[2 * r], pos[2 * r + 1]);
  for (let r = 0; r < run.robots; r++) {
    // Each robot's communication range: a light ring, so the map stays readable beneath.
    const [x, y] = at(r);
    ctx.strokeStyle = COLORS[r % COLORS.length];
    ctx.globalAlpha = 0.35;
    ctx.setLineDash([4, 4]);
    ctx.beginPath(); ctx.arc(x, y, run.comm_range * k, 0, 2 * Math.PI); ctx.stroke();
    ctx.setLineDash([]);
    ctx.globalAlpha = 0.03;
    ctx.fillStyle = COLORS[r % COLORS.length];
    ctx.fill();
    ctx.globalAlpha = 1;
  }
  for (const [i, j] of drawnLinks(step)) {
    const [x1, y1] = at(i - 1), [x2, y2] = at(j - 1);
    ctx.strokeStyle = "#2a2";
    ctx.lineWidth = 2;
    ctx.beginPath(); ctx.moveTo(x1, y1); ctx.lineTo(x2, y2); ctx.stroke();
  }
  if (selected !== null) {
    // The route each robot's kernel holds to the selected robot: an arrow to its next hop.
    ctx.strokeStyle = "#c00";
    ctx.lineWidth = 3;
    for (const [k, nh] of Object.entries(hops)) {
      if (nh === null || nh > run.robots) continue;
      const [x1, y1] = at(Number(k) - 1), [x2, y2] = at(nh - 1);
      ctx.beginPath(); ctx.moveTo(x1, y1); ctx.lineTo(x1 + 0.8 * (x2 - x1), y1 + 0.8 * (y2 - y1));
      ctx.stroke();
    }
  }
  ctx.lineWidth = 1;
  for (const [r, g] of Object.entries(run.live ? goals : {})) {
    // Each robot's current goal (its newest plan), a cross joined to the robot.
    const [x, y] = at(Number(r) - 1), [gx, gy] = toCanvas(g[0], g[1]);
    ctx.strokeStyle = COLORS[(Number(r) - 1) % COLORS.length];
    ctx.setLineDash([3, 3]);
    ctx.beginPath(); ctx.moveTo(x, y); ctx.lineTo(gx, gy); ctx.stroke();
    ctx.setLineDash([]);
    ctx.beginPath(); ctx.moveTo(gx - 5, gy - 5); ctx.lineTo(gx + 5, gy + 5);
    ctx.moveTo(gx - 5, gy + 5); ctx.lineTo(gx + 5, gy - 5); ctx.stroke();
  }
  for (let r = 0; r < run.robots; r++) {
    const c = COLORS[r % COLORS.length];
    ctx.strokeStyle = c;
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    for (let s = 0; s <= step; s += Math.max(1, Math.floor(step / 400))) {
      const [px, py] = toCanvas(run.positions[s][2 * r], run.positions[s][2 * r + 1]);
      if (s === 0) ctx.moveTo(px, py); else ctx.lineTo(px, py);
    }
    ctx.stroke();
    const [x, y] = at(r);
    ctx.fillStyle = c;
    ctx.strokeStyle = "#fff";
    ctx.lineWidth = 2;
    ctx.beginPath(); ctx.arc(x, y, 6, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
    ctx.font = "bold 13px sans-serif";
    ctx.lineWidth = 3;
    ctx.strokeText("r" + (r + 1), x + 8, y - 8);  // a white halo: readable over any line
    ctx.fillText("r" + (r + 1), x + 8, y - 8);
  }
  ctx.lineWidth = 1;
  const cov = run.coverage[step];
  const parts = [run.robots + " robots", run.comm_range + " m range",
                 drawnLinks(step).length + (drawnLinks(step).length === 1 ? " link" : " links")];
  if (cov !== undefined && cov !== null) parts.push("coverage " + (100 * cov).toFixed(1) + "%");
  parts.push("status " + run.status);
  document.getElementById("step").textContent = "step " + stepOf(step);
  document.getElementById("counters").textContent = parts.join(", ") + liveInfo;
}

let liveInfo = "";

function follow(frame) {
  // Live: each frame the run streams (server-sent events, at most 10 a second) is appended;
  // the slider follows the newest unless the user moved it back.
  const atEnd = Number(slider.value) >= run.steps;
  run.positions.push(frame.positions);
  linkSets.push(new Set(frame.links.map(([i, j]) => i + "-" + j)));
  run.coverage.push(frame.coverage);
  stepNos.push(frame.step);
  goals = frame.goals || {};
  if (frame.map_m) { run.map_m = frame.map_m; run.origin = frame.origin; }  // net up: grows
  run.snapshots = frame.snapshots;
  run.steps = run.positions.length - 1;
  slider.max = run.steps;
  // A network brought up by hand (`net up --view`) has no step loop: no deadlines, no
  // achieved scale; its own time scale is in run.time_scale.
  const timing = frame.scale == null
    ? (run.time_scale == null ? "" : ", time scale " + run.time_scale)
    : ", deadlines missed " + frame.missed + ", time scale achieved " + frame.scale;
  liveInfo = (selected === null ? "" : ", routes to r" + selected + " in red") + timing +
             (frame.messages_ps == null ? "" : ", messages " + frame.messages_ps + "/s") +
             (frame.routing_pps == null ? "" : ", routing packets " + frame.routing_pps + "/s") +
             (frame.ended ? " (run over)" : "");
  run.status = frame.ended ? "ended" : "running";
  if (atEnd) { slider.value = run.steps; }
  draw(Number(slider.value));
  document.body.dataset.frames = String(run.positions.length);
  document.body.dataset.links = String(drawnLinks(run.steps).length);
}

async function main() {
  run = await (await fetch("/api/run")).json();
  document.getElementById("title").textContent = (run.live ? "live: " : "replay: ") + run.run;
  slider.max = run.steps;
  buildLinkSets();
  canvas.addEventListener("click", (ev) => {
    if (!run.live || !run.positions.length) return;
    const pos = run.positions[Number(slider.value)];
    let best = null, bestD = 20;
    for (let r = 0; r < run.robots; r++) {
      const [x, y] = toCanvas(pos[2 * r], pos[2 * r + 1]);
      const d = Math.hypot(x - ev.offsetX, y - ev.offsetY);
      if (d < bestD) { best = r + 1; bestD = d; }
    }
    selected = best;
    hops = {};
    document.body.dataset.selected = String(selected);
  });
  setInterval(async () => {
    if (!run.live || selected === null) return;
    hops = await (await fetch("/api/routes?to=" + selected)).json();
    document.body.dataset.hops = JSON.stringify(hops);
  }, 1000);
  if (run.live) {
    linkSets = [];
    const events = new EventSource("/api/live");
    events.onmessage = (e) => follow(JSON.parse(e.data));
  }
  if (run.map) {  // the empty terrain has no picture: nothing to ask for
    const img = new Image();
    img.onload = () => { mapImg = img; draw(Number(slider.value)); };
    img.src = "/map.png";
  }
  slider.addEventListener("input", () => draw(Number(slider.value)));
  document.getElementById("play").addEventListener("click", () => {
    if (playing) { clearInterval(playing); playing = null; return; }
    playing = setInterval(() => {
      const s = Number(slider.value) + 5;
      if (s > run.steps) { clearInterval(playing); playing = null; return; }
      slider.value = s; draw(s);
    }, 50);
  });
  if (run.positions.length) draw(0);
  document.body.dataset.ready = "1";
}
main();
