// controlmm studio: the page. Talks to the JSON API of the same server (controlmm/studio/server.py).
"use strict";

const $ = (id) => document.getElementById(id);
const MODE = document.body.dataset.mode;
const FIELD_INPUTS = { scene: ["scene", "scene-path"], robot: ["robot"], text: ["text"], seconds: ["seconds"],
  seed: ["seed"], rounds: ["rounds"], preset: ["preset"], control: ["targets"], render: ["render"],
  plots: ["plots"] };
const state = { info: null, scene: null, geometries: {}, edits: [], active: -1, job: null, view: null,
  playing: false, textTouched: false, plans: [], loading: null };
const viewer = new window.StudioViewer($("view"), $("labels"));
window.studio = { state, viewer };  // for people poking at the page from the console (and the tests)
if (!viewer.ok) $("nogl").hidden = false;

async function api(method, url, body) {
  const init = { method, headers: {} };
  if (body !== undefined) { init.headers["Content-Type"] = "application/json"; init.body = JSON.stringify(body); }
  let res;
  try { res = await fetch(url, init); } catch (err) {
    return { ok: false, status: 0, data: { error: `the studio server does not answer (${err.message})` } };
  }
  let data = null;
  try { data = await res.json(); } catch (err) { data = { error: `HTTP ${res.status}` }; }
  return { ok: res.ok, status: res.status, data };
}

function clearErrors() {
  document.querySelectorAll(".error").forEach((el) => { el.textContent = ""; });
  document.querySelectorAll(".invalid").forEach((el) => el.classList.remove("invalid"));
}

function showError(field, message) {
  const el = $("error-" + field) || $("error-general");
  el.textContent = message;
  for (const id of FIELD_INPUTS[field] || []) if ($(id)) $(id).classList.add("invalid");
}

const esc = (s) => String(s).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);
const fmt = (v, d = 3) => (v === null || v === undefined ? "-" : Number(v).toFixed(d));

// ------------------------------------------------------------------------------ set-up
async function init() {
  $("mode-name").textContent = MODE === "view" ? "view" : "studio";
  const res = await api("GET", "/api/info");
  if (!res.ok) { $("model-state").textContent = res.data.error; return; }
  const info = state.info = res.data;
  fill($("scene"), info.scenes, info.default_scene);
  fill($("robot"), info.robots.length ? info.robots : ["g1"], info.defaults.robot);
  fill($("preset"), info.presets, info.defaults.preset);
  $("seed").value = info.defaults.seed;
  $("rounds").value = info.defaults.rounds;
  $("render").checked = !!info.defaults.render;
  $("plots").checked = !!info.defaults.plots;
  bindControls();
  await refreshPlans();
  if (MODE === "studio") {
    watchModel();
    await loadScene(true);
  } else if (state.plans.length) {
    await openPlan(state.plans[0].id);
  }
}

function fill(select, values, chosen) {
  select.innerHTML = values.map((v) => `<option${v === chosen ? " selected" : ""}>${esc(v)}</option>`).join("");
}

async function watchModel() {
  const res = await api("GET", "/api/info");
  if (!res.ok) return;
  const m = res.data.model;
  $("model-state").textContent = m === "ready" ? "model loaded: plans start at once"
    : m === "loading" ? "loading the model... (plans wait for it)" : `model: ${m} ${res.data.model_error || ""}`;
  $("model-state").dataset.model = m;
  if (m === "loading") setTimeout(watchModel, 700);
}

function sceneRef() { return $("scene-path").value.trim() || $("scene").value; }

// A plan sent while a scene loads waits for it (its targets replace the last scene's first).
function loadScene(replaceTargets) {
  state.loading = fetchScene(replaceTargets);
  return state.loading;
}

async function fetchScene(replaceTargets) {
  clearErrors();
  const q = new URLSearchParams({ scene: sceneRef(), robot: $("robot").value });
  const res = await api("GET", "/api/scene?" + q);
  if (!res.ok) { showError(res.data.field || "scene", res.data.error); return; }
  const doc = state.scene = res.data;
  $("scene-description").textContent = doc.description || "";
  if (!state.textTouched) $("text").value = doc.suggested_prompt || "";
  $("text").placeholder = doc.suggested_prompt || "a person walks forward";
  if (replaceTargets) {
    state.edits = doc.suggested_targets.map((t) => ({ joint: t.joint, frame: t.frame, position: t.position.slice() }));
    state.active = -1;
    renderRows();
  }
  await showGeometry(doc.geometry);
  if (!state.view || state.view.geometry !== doc.geometry) { state.view = null; viewer.clearView(); resetDetails(); }
}

async function showGeometry(gid) {
  if (!state.geometries[gid]) {
    const res = await api("GET", "/api/geometry/" + gid);
    if (!res.ok) { showError("general", res.data.error); return; }
    res.data.id = gid;
    state.geometries[gid] = res.data;
  }
  viewer.setGeometry(state.geometries[gid]);
}

// ------------------------------------------------------------------------------ targets
function renderRows() {
  const joints = state.info ? state.info.joints : [];
  const body = $("targets").querySelector("tbody");
  body.innerHTML = state.edits.map((e, i) => `
    <tr data-row="${i}" class="${i === state.active ? "active" : ""}">
      <td><select data-k="joint">${joints.map((j) => `<option${j === e.joint ? " selected" : ""}>${j}</option>`).join("")}</select></td>
      <td><input data-k="frame" type="number" step="1" value="${e.frame}"></td>
      ${[0, 1, 2].map((k) => `<td><input data-k="p${k}" type="number" step="0.01" value="${fmt(e.position[k])}"></td>`).join("")}
      <td><button type="button" data-k="remove" title="remove">x</button></td>
    </tr>`).join("");
  body.querySelectorAll("tr").forEach((tr) => {
    const i = Number(tr.dataset.row);
    tr.addEventListener("click", () => { state.active = i; markActive(); });
    tr.querySelectorAll("[data-k]").forEach((el) => {
      const k = el.dataset.k;
      if (k === "remove") {
        el.addEventListener("click", (ev) => {
          ev.stopPropagation(); state.edits.splice(i, 1); state.active = -1; renderRows();
        });
        return;
      }
      el.addEventListener("input", () => {
        const e = state.edits[i];
        if (k === "joint") e.joint = el.value;
        else if (k === "frame") e.frame = el.value === "" ? NaN : Number(el.value);
        else e.position[Number(k[1])] = el.value === "" ? NaN : Number(el.value);
        syncEdits();
      });
    });
  });
  syncEdits();
}

function markActive() {
  $("targets").querySelectorAll("tbody tr").forEach((tr) => tr.classList.toggle("active", Number(tr.dataset.row) === state.active));
  syncEdits();
}

function syncEdits() {
  viewer.edits = state.edits.map((e, i) => ({ ...e, active: i === state.active }));
  viewer.requestDraw();
}

function addTarget() {
  const s = state.scene ? state.scene.start : { x: 0, y: 0, yaw: 0 };
  state.edits.push({ joint: "right_wrist", frame: 60,
    position: [s.x + 0.8 * Math.cos(s.yaw), s.y + 0.8 * Math.sin(s.yaw), 1.0].map((v) => Math.round(v * 1000) / 1000) });
  state.active = state.edits.length - 1;
  renderRows();
}

function pickTarget(clientX, clientY) {
  if (state.active < 0 || MODE !== "studio") return;
  const e = state.edits[state.active];
  const p = viewer.pick(clientX, clientY, Number.isFinite(e.position[2]) ? e.position[2] : 1.0);
  if (!p) return;
  e.position[0] = Math.round(p[0] * 1000) / 1000;
  e.position[1] = Math.round(p[1] * 1000) / 1000;
  renderRows();
}

async function loadSpecFile(file) {
  clearErrors();
  let spec;
  try { spec = JSON.parse(await file.text()); } catch (err) {
    showError("control", `${file.name} is not JSON: ${err.message}`); return;
  }
  const res = await api("POST", "/api/spec", { scene: sceneRef(), robot: $("robot").value, control: spec });
  if (!res.ok) { showError(res.data.field || "control", res.data.error); return; }
  state.edits = res.data.targets.map((t) => ({ joint: t.joint, frame: t.frame, position: t.position.slice() }));
  state.active = -1;
  renderRows();
}

function controlSpec() {
  if (!state.edits.length) return null;
  return { coords: "world", constraints: state.edits.map((e) => ({ joint: e.joint, frame: e.frame, position: e.position })) };
}

// ------------------------------------------------------------------------------ planning
function planRequest() {
  const body = { scene: sceneRef(), robot: $("robot").value, preset: $("preset").value, render: $("render").checked,
    plots: $("plots").checked };
  const text = $("text").value.trim();
  if (text) body.text = text;
  for (const k of ["seed", "rounds"]) body[k] = $(k).value === "" ? NaN : Number($(k).value);
  if ($("seconds").value !== "") body.seconds = Number($("seconds").value);
  body.control = controlSpec();
  return body;
}

async function startPlan() {
  if (state.loading) await state.loading;
  clearErrors();
  const body = planRequest();
  for (const k of ["seed", "rounds", "seconds"]) {
    if (k in body && !Number.isFinite(body[k])) { showError(k, `${k} must be a number`); return; }
  }
  for (const e of state.edits) {
    if (!Number.isFinite(e.frame) || !e.position.every(Number.isFinite)) {
      showError("control", `target ${e.joint}: frame and x, y, z must be numbers`); return;
    }
  }
  $("plan-button").disabled = true;
  const res = await api("POST", "/api/plans", body);
  $("plan-button").disabled = false;
  if (!res.ok) { showError(res.data.field || "general", res.data.error); return; }
  state.job = res.data.id;
  setStatus("queued", `plan ${res.data.id}: queued`);
  $("progress").innerHTML = "";
  await refreshPlans();
  poll(res.data.id);
}

function setStatus(status, text) {
  $("status").dataset.status = status;
  $("status").textContent = text;
}

async function poll(id) {
  const res = await api("GET", `/api/plans/${id}`);
  if (!res.ok) { setStatus("failed", res.data.error); return; }
  const job = res.data;
  $("progress").innerHTML = job.progress.map((l) => `<li>${esc(l)}</li>`).join("");
  const total = (job.rounds_allowed || 0) + 1;
  const done = job.status === "done" || job.status === "failed" ? total : (job.round === null ? 0.3 : job.round + 0.5);
  $("progress-fill").style.width = `${Math.min(100, (100 * done) / total).toFixed(0)}%`;
  if (job.status === "done") {
    setStatus("done", `plan ${id}: ${job.report.passed ? "PASSED" : "FAILED the checks"} in ${fmt(job.seconds, 1)} s`);
    await refreshPlans();
    await openPlan(id);
    return;
  }
  if (job.status === "failed") {
    setStatus("failed", `plan ${id} failed: ${job.error}`);
    showError("general", job.error);
    await refreshPlans();
    return;
  }
  const last = job.progress.length ? job.progress[job.progress.length - 1] : "waiting for the model";
  setStatus(job.status, `plan ${id}: ${job.status}${job.round !== null ? ` (round ${job.round} of up to ${total})` : ""} - ${last}`);
  setTimeout(() => poll(id), 400);
}

async function refreshPlans() {
  const res = await api("GET", "/api/plans");
  if (!res.ok) return;
  state.plans = res.data.plans;
  $("plans").innerHTML = state.plans.map((p) => `<li><a data-id="${esc(p.id)}">${esc(p.id)}</a> ${esc(p.status)}` +
    `${p.passed === undefined ? "" : p.passed ? " <span class=pass>pass</span>" : " <span class=fail>fail</span>"}` +
    `${p.scene ? ` <span class=muted>${esc(p.scene)}</span>` : ""}</li>`).join("");
  $("plans").querySelectorAll("a").forEach((a) => a.addEventListener("click", () => openPlan(a.dataset.id)));
}

// ------------------------------------------------------------------------------ results
async function openPlan(id) {
  const [jobRes, viewRes] = await Promise.all([api("GET", `/api/plans/${id}`), api("GET", `/api/plans/${id}/view`)]);
  if (!viewRes.ok) { showError("general", viewRes.data.error); return; }
  const view = state.view = viewRes.data;
  view.id = id;
  await showGeometry(view.geometry);
  viewer.setView(view);
  const chosen = view.rounds[viewer.round];
  $("timeline").max = String(Math.round(viewer.duration() * chosen.fps));
  $("timeline").value = "0";
  $("timeline").disabled = false;
  $("play").disabled = false;
  $("round-pick").innerHTML = view.rounds.map((r, i) =>
    `<option value="${i}"${i === viewer.round ? " selected" : ""}>round ${r.index}${r.index === view.chosen ? " (chosen)" : ""}</option>`).join("");
  $("side-by-side").disabled = view.rounds.length < 2;
  if (view.rounds.length < 2) { $("side-by-side").checked = false; viewer.show.sideBySide = false; }
  if (jobRes.ok && jobRes.data.status === "done" && !state.job) setStatus("done", `plan ${id}`);
  renderDetails(view);
  seek(0);
}

function resetDetails() {
  $("verdict").textContent = "plan something, or pick a plan";
  for (const id of ["rounds-table", "failures", "target-results", "downloads"]) $(id).innerHTML = "";
  $("timeline").disabled = true; $("play").disabled = true;
  drawClearance();
}

function renderDetails(view) {
  const rep = view.report;
  $("verdict").innerHTML = `<span class="${view.passed ? "pass" : "fail"}">${view.passed ? "PASSED" : "FAILED"}</span>` +
    ` ${esc(view.scene)} / ${esc(view.robot)}: "${esc(view.text)}"<br>` +
    `penetration ${fmt(rep.max_penetration_m * 1000, 1)} mm, floor ${fmt(rep.floor_penetration_m * 1000, 1)} mm, ` +
    `min clearance ${rep.min_clearance_m === null ? "-" : fmt(rep.min_clearance_m * 1000, 1) + " mm"}, ` +
    `self-collision ${rep.self_collision_frames} frames, foot sliding ${fmt(rep.foot_sliding_m * 1000, 1)} mm` +
    (view.rounds_drawn === "chosen" ? `<br><span class="muted">a plan folder keeps the chosen round's trajectory: other rounds show their figures</span>` : "");
  const figs = view.round_figures.length ? view.round_figures : view.rounds.map((r) => r.figures);
  $("rounds-table").innerHTML = `<tr><th>round</th><th>verdict</th><th>failures</th><th>penetration mm</th><th>worst target cm</th><th>s</th></tr>` +
    figs.map((f) => `<tr data-round="${f.round}"><td>${f.round}${f.round === view.chosen ? " *" : ""}</td>` +
      `<td class="${f.passed ? "pass" : "fail"}">${f.passed ? "pass" : "fail"}</td><td>${f.failures}</td>` +
      `<td>${fmt(f.max_penetration_m * 1000, 1)}</td>` +
      `<td>${f.constraint_errors_m && f.constraint_errors_m.length ? fmt(Math.max(...f.constraint_errors_m) * 100, 2) : "-"}</td>` +
      `<td>${f.seconds ? fmt(Object.values(f.seconds).reduce((a, b) => a + b, 0), 1) : "-"}</td></tr>`).join("");
  renderRoundDetails();
  $("downloads").innerHTML = view.files.map((f) =>
    `<li><a href="/api/plans/${encodeURIComponent(view.id)}/files/${f.split("/").map(encodeURIComponent).join("/")}" download>${esc(f)}</a></li>`).join("");
}

const METRES = ["obstacle_penetration", "floor_penetration", "self_collision", "foot_sliding", "floating", "tracking_fall"];
const depth = (f) => (METRES.includes(f.kind) ? `depth ${fmt(f.depth * 1000, 1)} mm` : `worst ${fmt(f.depth, 3)}`);

function renderRoundDetails() {
  const view = state.view;
  if (!view) return;
  const r = view.rounds[viewer.round];
  const errors = r.failures.filter((f) => f.severity === "error");
  const warnings = r.failures.length - errors.length;
  $("failures").innerHTML = (errors.length ? "" : "<li class=muted>no failing checks in this round</li>") +
    errors.map((f) => `<li data-frame="${f.frame_start}"><b>${esc(f.kind)}</b> ${esc(f.robot_body || "")}` +
      `${f.obstacle_geom ? " / " + esc(f.obstacle_geom) : ""} frames ${f.frame_start}-${f.frame_end}` +
      ` (${fmt(f.frame_start / r.fps, 2)}-${fmt(f.frame_end / r.fps, 2)} s), ${depth(f)}</li>`).join("") +
    (warnings ? `<li class=muted>${warnings} warnings (report.json)</li>` : "");
  $("failures").querySelectorAll("li[data-frame]").forEach((li) =>
    li.addEventListener("click", () => seek(Number(li.dataset.frame) / r.fps)));
  $("target-results").innerHTML = r.targets.length ? `<tr><th>joint@frame</th><th>target</th><th>reached</th><th>error cm</th></tr>` +
    r.targets.map((t) => `<tr><td>${esc(t.joint)}@${t.frame}</td><td>${t.target.map((v) => fmt(v, 2)).join(", ")}</td>` +
      `<td>${t.achieved.map((v) => fmt(v, 2)).join(", ")}</td>` +
      `<td class="${t.error_m !== null && t.error_m > 0.02 ? "fail" : "pass"}">${t.error_m === null ? "-" : fmt(t.error_m * 100, 2)}</td></tr>`).join("")
    : "<tr><td class=muted>no targets</td></tr>";
}

// ------------------------------------------------------------------------------ time
function seek(t) {
  const dur = viewer.duration();
  viewer.time = Math.min(Math.max(t, 0), dur);
  if (state.view) {
    const r = state.view.rounds[viewer.round];
    $("timeline").value = String(Math.round(viewer.time * r.fps));
  }
  $("time").textContent = `${viewer.time.toFixed(2)} s`;
  $("time").dataset.frame = $("timeline").value;
  viewer.requestDraw();
  drawClearance();
}

function togglePlay() {
  state.playing = !state.playing;
  $("play").textContent = state.playing ? "pause" : "play";
  if (!state.playing) return;
  let last = performance.now();
  const step = (now) => {
    if (!state.playing) return;
    const dur = viewer.duration();
    let t = viewer.time + (now - last) / 1000;
    last = now;
    if (t > dur) t = 0;
    seek(t);
    requestAnimationFrame(step);
  };
  requestAnimationFrame(step);
}

function drawClearance() {
  const c = $("clearance"), ctx = c.getContext("2d"), dpr = window.devicePixelRatio || 1;
  const w = c.width = Math.round(c.getBoundingClientRect().width * dpr), h = c.height = Math.round(150 * dpr);
  ctx.clearRect(0, 0, w, h);
  ctx.font = `${11 * dpr}px system-ui`;
  const view = state.view;
  if (!view) { ctx.fillStyle = "#6a7385"; ctx.fillText("clearance to the nearest obstacle appears here after a plan", 10 * dpr, 20 * dpr); return; }
  const dur = Math.max(viewer.duration(), 1e-3), lo = -0.05, hi = 0.3, left = 44 * dpr, right = w - 10 * dpr;
  const X = (t) => left + (right - left) * t / dur, Y = (v) => 8 * dpr + (h - 26 * dpr) * (hi - Math.min(hi, Math.max(lo, v))) / (hi - lo);
  const r = view.rounds[viewer.round];
  ctx.fillStyle = "rgba(230, 40, 30, 0.16)";
  for (const f of r.failures) {
    if (f.severity !== "error") continue;
    ctx.fillRect(X(f.frame_start / r.fps), 0, Math.max(2, X((f.frame_end + 1) / r.fps) - X(f.frame_start / r.fps)), h - 18 * dpr);
  }
  ctx.strokeStyle = "#999"; ctx.lineWidth = 1;
  ctx.beginPath(); ctx.moveTo(left, Y(0)); ctx.lineTo(right, Y(0)); ctx.stroke();
  const tol = view.tolerances.obstacle_penetration_m;
  if (tol) { ctx.setLineDash([4, 4]); ctx.strokeStyle = "#d33"; ctx.beginPath(); ctx.moveTo(left, Y(-tol)); ctx.lineTo(right, Y(-tol)); ctx.stroke(); ctx.setLineDash([]); }
  const palette = ["#2457c5", "#e0892a", "#2a9d4b", "#9b38c9", "#c0262d", "#5d6b82"];
  view.rounds.forEach((rd, i) => {
    ctx.strokeStyle = palette[i % palette.length]; ctx.lineWidth = (i === viewer.round ? 2.2 : 1) * dpr;
    ctx.beginPath();
    let pen = false;
    rd.clearance.forEach((v, k) => {
      if (v === null) { pen = false; return; }
      const x = X(k / rd.fps), y = Y(v);
      if (pen) ctx.lineTo(x, y); else ctx.moveTo(x, y);
      pen = true;
    });
    ctx.stroke();
    ctx.fillStyle = palette[i % palette.length];
    ctx.fillText(`round ${rd.index}`, right - 70 * dpr * (view.rounds.length - i), 16 * dpr);
  });
  ctx.fillStyle = "#3b4456";
  ctx.fillText("clearance (m)", 2, 16 * dpr);
  for (const v of [0, 0.1, 0.2, 0.3]) ctx.fillText(v.toFixed(1), 4 * dpr, Y(v) + 4 * dpr);
  ctx.fillText(`${dur.toFixed(1)} s`, right - 30 * dpr, h - 4 * dpr);
  ctx.strokeStyle = "#111"; ctx.lineWidth = 1.5 * dpr;
  ctx.beginPath(); ctx.moveTo(X(viewer.time), 0); ctx.lineTo(X(viewer.time), h - 18 * dpr); ctx.stroke();
  c.dataset.rounds = String(view.rounds.length);
  c.onclick = (e) => {
    const rect = c.getBoundingClientRect();
    seek(((e.clientX - rect.left) * dpr - left) / (right - left) * dur);
  };
}

// ------------------------------------------------------------------------------ wiring
function bindControls() {
  $("scene").addEventListener("change", () => { $("scene-path").value = ""; loadScene(true); });
  $("scene-path").addEventListener("change", () => loadScene(true));
  $("robot").addEventListener("change", () => loadScene(false));
  $("text").addEventListener("input", () => { state.textTouched = true; });
  $("add-target").addEventListener("click", addTarget);
  $("clear-targets").addEventListener("click", () => { state.edits = []; state.active = -1; renderRows(); });
  $("spec-file").addEventListener("change", (e) => { if (e.target.files.length) loadSpecFile(e.target.files[0]); e.target.value = ""; });
  $("plan-button").addEventListener("click", startPlan);
  $("play").addEventListener("click", togglePlay);
  $("timeline").addEventListener("input", () => {
    if (!state.view) return;
    seek(Number($("timeline").value) / state.view.rounds[viewer.round].fps);
  });
  $("show-robot").addEventListener("change", (e) => { viewer.show.robot = e.target.checked; viewer.requestDraw(); });
  $("show-human").addEventListener("change", (e) => { viewer.show.human = e.target.checked; viewer.requestDraw(); });
  $("show-contacts").addEventListener("change", (e) => { viewer.show.contacts = e.target.checked; viewer.requestDraw(); });
  $("side-by-side").addEventListener("change", (e) => { viewer.show.sideBySide = e.target.checked; viewer.requestDraw(); });
  $("round-pick").addEventListener("change", (e) => {
    viewer.round = Number(e.target.value); renderRoundDetails(); seek(viewer.time);
  });
  viewer.onPick = pickTarget;
  window.addEventListener("resize", drawClearance);
}

init();
