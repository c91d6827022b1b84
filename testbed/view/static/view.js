// The replay page: draws one step of a finished run from /api/run (testbed/view/replay.py):
// the map faint, each robot with its path so far and its communication range, the links
// of that step. No framework and no build step: this file is what the browser runs.
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
const snaps = new Map();  // the display robot's merged-map snapshots, by step, once loaded

function stepOf(i) { return run.live ? stepNos[i] : i; }

function snapshotFor(i) {
  // The newest display snapshot at or before the step shown, loaded on first use.
  const step = stepOf(i);
  let best = null;
  for (const s of run.snapshots || []) if (s <= step && (best === null || s > best)) best = s;
  if (best === null) return null;
  if (!snaps.has(best)) {
    const img = new Image();
    img.onload = () => draw(Number(slider.value));
    img.src = "/display.png?step=" + best;
    snaps.set(best, img);
  }
  const img = snaps.get(best);
  return img.complete && img.naturalWidth ? img : null;
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
  const k = canvas.width / Math.max(wm, hm);
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (mapImg) {  // the ground truth, faint
    ctx.globalAlpha = 0.3;
    ctx.drawImage(mapImg, 0, 0, wm * k, hm * k);
    ctx.globalAlpha = 1;
  }
  const snap = snapshotFor(step);
  if (snap) {  // the display robot's merged map over it (its newest snapshot)
    ctx.globalAlpha = 0.35;
    ctx.drawImage(snap, 0, 0, wm * k, hm * k);
    ctx.globalAlpha = 1;
  }
  ctx.strokeStyle = "#999";
  ctx.strokeRect(0, 0, wm * k, hm * k);
  const pos = run.positions[step];
  const at = (r) => [pos[2 * r] * k, pos[2 * r + 1] * k];
  for (const key of linksAt(step)) {
    const [i, j] = key.split("-").map(Number);
    if (i > run.robots || j > run.robots) continue;  // the display's links
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
    const [x, y] = at(Number(r) - 1), gx = g[0] * k, gy = g[1] * k;
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
    ctx.beginPath();
    for (let s = 0; s <= step; s += Math.max(1, Math.floor(step / 400))) {
      const p = run.positions[s];
      if (s === 0) ctx.moveTo(p[2 * r] * k, p[2 * r + 1] * k);
      else ctx.lineTo(p[2 * r] * k, p[2 * r + 1] * k);
    }
    ctx.stroke();
    const [x, y] = at(r);
    ctx.globalAlpha = 0.08;
    ctx.fillStyle = c;
    ctx.beginPath(); ctx.arc(x, y, run.comm_range * k, 0, 2 * Math.PI); ctx.fill();
    ctx.globalAlpha = 1;
    ctx.beginPath(); ctx.arc(x, y, 5, 0, 2 * Math.PI); ctx.fill();
    ctx.fillText("r" + (r + 1), x + 6, y - 6);
  }
  const cov = run.coverage[step];
  document.getElementById("step").textContent = "step " + stepOf(step);
  document.getElementById("counters").textContent =
    run.robots + " robots, " + run.comm_range + " m range, " + linksAt(step).size +
    " links, coverage " + (cov === undefined || cov === null ? "?" : (100 * cov).toFixed(1) + "%") +
    ", status " + run.status + liveInfo;
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
  run.snapshots = frame.snapshots;
  run.steps = run.positions.length - 1;
  slider.max = run.steps;
  liveInfo = (selected === null ? "" : ", routes to r" + selected + " in red") +
             ", deadlines missed " + frame.missed + ", time scale achieved " + frame.scale +
             (frame.messages_ps == null ? "" : ", messages " + frame.messages_ps + "/s") +
             (frame.routing_pps == null ? "" : ", routing packets " + frame.routing_pps + "/s") +
             (frame.ended ? " (run over)" : "");
  run.status = frame.ended ? "ended" : "running";
  if (atEnd) { slider.value = run.steps; }
  draw(Number(slider.value));
  document.body.dataset.frames = String(run.positions.length);
  document.body.dataset.links = String(linksAt(run.steps).size);
}

async function main() {
  run = await (await fetch("/api/run")).json();
  document.getElementById("title").textContent = (run.live ? "live: " : "replay: ") + run.run;
  slider.max = run.steps;
  buildLinkSets();
  canvas.addEventListener("click", (ev) => {
    if (!run.live || !run.positions.length) return;
    const [wm, hm] = run.map_m;
    const k = canvas.width / Math.max(wm, hm);
    const pos = run.positions[Number(slider.value)];
    let best = null, bestD = 20;
    for (let r = 0; r < run.robots; r++) {
      const d = Math.hypot(pos[2 * r] * k - ev.offsetX, pos[2 * r + 1] * k - ev.offsetY);
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
  const img = new Image();
  img.onload = () => { mapImg = img; draw(Number(slider.value)); };
  img.src = "/map.png";
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
