/* The live view's page: polls /status.json and /data.json (incrementally: the readings after
   those it has, the reduced points changed since its reduction version), fetches each
   panel's reference curves from /model.json once, and relays pause, resume and abort. Its
   requests carry the viewer's key in the cookie the keyed page visit set. */
"use strict";

const POLL_MS = 1000;
const PALETTE = ["#1f77b4", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#ff7f0e", "#7f7f7f", "#393b79"];
const KIND_COLOURS = { dark: "#6b7280", beam: "#111111", signature: "#d62728" };
const FLAG_COLOUR = "#d62728", RETRY_COLOUR = "#ff9f1c", MODEL_COLOUR = "#c0392b";
const ACTIVE = ["starting", "running", "pausing", "paused", "suspended"];

const view = {
  raw: [], groups: new Map(), reduced: new Map(), version: 0, panels: [],
  models: new Map(), asked: new Set(), modelNote: "", status: null, rawDirty: true, bsdfDirty: true,
};

const $ = (id) => document.getElementById(id);

function hms(seconds) {
  if (seconds === null || seconds === undefined || !isFinite(seconds)) return "-";
  const s = Math.max(0, Math.round(seconds));
  const h = Math.floor(s / 3600), m = Math.floor((s % 3600) / 60), r = s % 60;
  return (h ? `${h}:${String(m).padStart(2, "0")}` : `${m}`) + `:${String(r).padStart(2, "0")}`;
}

async function getJSON(url) {
  const reply = await fetch(url, { cache: "no-store" });
  if (!reply.ok) throw new Error(`${url}: HTTP ${reply.status}`);
  return reply.json();
}

/* -- status ------------------------------------------------------------------------------ */

function renderStatus(s) {
  $("run-name").textContent = s.run;
  document.title = `${s.status} - ${s.run} - gonio watch`;
  $("run-facts").textContent = [`plan ${s.plan}`, `instrument ${s.instrument}`,
    s.sample ? `sample ${s.sample}` : "no [sample]", s.emulated === true ? "emulated bench" : (s.emulated ? `emulated: ${s.emulated}` : "real devices")].join(" · ");
  const status = $("status");
  status.textContent = s.status;
  status.className = "status " + s.status.replace(/\s+/g, "-");
  $("reason").textContent = s.reason || (s.status === "not running" ? "no scan process answers on the control channel; `gonio scan --resume RUN` continues the run" : "");
  $("readings").textContent = s.readings;
  $("planned").textContent = s.planned;
  $("progress").value = s.planned ? s.readings / s.planned : 0;
  $("elapsed").textContent = hms(s.elapsed_s);
  $("eta").textContent = s.eta_s === null ? s.eta_from : `${hms(s.eta_s)} (${s.eta_from})`;
  $("positions").innerHTML = Object.entries(s.positions).map(([role, deg]) => `<tr><td>${role}</td><td>${deg.toFixed(3)}°</td></tr>`).join("");
  const last = s.last;
  $("last").textContent = last ? `#${last.index} ${last.kind}${last.side ? " " + last.side : ""}${last.plan_theta_i_deg !== null ? `, θi ${last.plan_theta_i_deg}°, θo ${last.plan_theta_o_deg}°` : ""}` : "";
  renderControls(s);
  renderAlerts(s);
  $("footer").textContent = `gonio watch · polled every ${POLL_MS / 1000} s · ${new Date().toLocaleTimeString()}`;
}

function renderControls(s) {
  const enabled = s.control.enabled;
  const state = s.status;
  const can = { pause: ["starting", "running"].includes(state), resume: ["paused", "pausing"].includes(state), abort: ACTIVE.includes(state) };
  for (const action of ["pause", "resume", "abort"]) {
    const button = $(action);
    button.disabled = !(enabled && can[action]);
    button.title = enabled ? (can[action] ? `${action} the scan` : `the scan is ${state}`) : s.control.why;
  }
  if (!enabled) $("control-note").textContent = s.control.why;
  else if (!$("control-note").dataset.reply) $("control-note").textContent = "connected to the scan's control channel";
}

function renderAlerts(s) {
  const out = [];
  if (s.damage) out.push(`<div class="damage">damaged run: ${escapeHtml(s.damage)}</div>`);
  if (s.incomplete) out.push(`<div class="damage">${escapeHtml(s.incomplete)}</div>`);
  for (const sus of s.suspensions || []) {
    const until = sus.resumed_t_s === null || sus.resumed_t_s === undefined ? "not resumed yet" : `resumed at ${hms(sus.resumed_t_s)}`;
    out.push(`<div>suspended at reading ${sus.index} (${hms(sus.t_s)} into the run): ${escapeHtml(sus.reason)}; ${until}</div>`);
  }
  $("alerts").innerHTML = out.join("");
}

function escapeHtml(text) {
  return String(text).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);
}

async function control(action) {
  if (action === "abort" && !window.confirm("Abort the scan? It stops the axes; `gonio scan --resume` can continue it later.")) return;
  const note = $("control-note");
  try {
    const reply = await fetch(`/control/${action}`, { method: "POST", headers: { "Content-Type": "application/json" }, body: "{}" });
    const body = await reply.json();
    note.textContent = body.ok ? `${action}: the scan is ${body.state}` : `${action} refused: ${body.error}`;
  } catch (e) {
    note.textContent = `${action} failed: ${e.message}`;
  }
  note.dataset.reply = "1";
  tick(false);
}

/* -- data -------------------------------------------------------------------------------- */

function groupOf(p) {
  if (p.kind !== "sample") return { key: p.kind, label: p.kind, colour: KIND_COLOURS[p.kind] || "#444" };
  const key = `${p.side} ${p.ti}`;
  if (!view.groups.has(key)) view.groups.set(key, PALETTE[view.groups.size % PALETTE.length]);
  return { key, label: `${p.side}, θi ${p.ti}°`, colour: view.groups.get(key) };
}

function mergeData(d) {
  if (d.since < view.raw.length) view.raw = view.raw.slice(0, d.since);
  if (d.raw.length) { view.raw.push(...d.raw); view.rawDirty = true; }
  const r = d.reduced;
  if (r.replace) view.reduced.clear();
  for (const p of r.points) view.reduced.set(p.i, p);
  if (r.version !== view.version || r.replace || r.points.length) view.bsdfDirty = true;
  if (JSON.stringify(r.panels) !== JSON.stringify(view.panels)) view.bsdfDirty = true;
  view.version = r.version;
  view.panels = r.panels;
  view.reduction = r;
  const missing = r.panels.map((p) => p.key).filter((k) => !view.asked.has(k));
  if (missing.length) fetchModels(missing);
}

async function fetchModels(keys) {
  keys.forEach((k) => view.asked.add(k));
  try {
    const m = await getJSON(`/model.json?keys=${encodeURIComponent(keys.join(","))}`);
    view.modelNote = m.note;
    for (const [key, curves] of Object.entries(m.curves)) view.models.set(key, curves);
    if (m.note === "the run is not reduced yet") keys.forEach((k) => view.asked.delete(k));
    view.bsdfDirty = true;
    renderBsdf();
  } catch (e) {
    keys.forEach((k) => view.asked.delete(k));
  }
}

/* -- plots ------------------------------------------------------------------------------- */

function renderRaw() {
  if (!view.rawDirty) return;
  view.rawDirty = false;
  const seen = new Map();
  const points = view.raw.map((p) => {
    const g = groupOf(p);
    seen.set(g.key, g);
    const saturated = p.flags.includes("saturated"), invalid = p.flags.includes("invalid");
    return {
      x: p.arm, y: p.p, color: saturated || invalid ? FLAG_COLOUR : g.colour, hollow: saturated || invalid,
      ring: p.flags.includes("retried") ? RETRY_COLOUR : null,
      tip: `#${p.i} ${g.label}: arm ${p.arm.toFixed(2)}°, ${p.p === null ? "no reading" : p.p.toPrecision(4) + " W"} (range ${p.range} W)${p.flags.length ? ", " + p.flags.join(", ") : ""}`,
    };
  });
  GonioPlot.draw($("raw-plot"), {
    x: [0, 360], xticks: [0, 45, 90, 135, 180, 225, 270, 315, 360],
    y: GonioPlot.logRange(view.raw.map((p) => p.p), [-12, -2]),
    xlabel: "arm angle (deg; 180 = the straight-through beam)", ylabel: "raw power (W)", points,
  });
  const entries = [...seen.values()].map((g) => ({ kind: "point", color: g.colour, label: g.label }));
  entries.push({ kind: "hollow", color: FLAG_COLOUR, label: "saturated" }, { kind: "below", color: FLAG_COLOUR, label: "invalid (no reading) / not positive" }, { kind: "ring", color: RETRY_COLOUR, label: "retried" });
  GonioPlot.legend($("raw-legend"), entries);
}

function renderBsdf() {
  if (!view.bsdfDirty) return;
  view.bsdfDirty = false;
  const r = view.reduction;
  const state = $("reduction-state");
  if (!r || r.state !== "reduced") {
    state.textContent = r ? `${r.state}: ${r.reason}` : "waiting for data";
    state.dataset.state = r ? r.state : "waiting";
    $("panels").innerHTML = "";
    $("bsdf-legend").innerHTML = "";
    return;
  }
  state.dataset.state = r.state;
  const flagged = [...view.reduced.values()].filter((p) => !p.valid).length;
  state.textContent = `reduced ${view.reduced.size} points of the first ${r.readings} readings (${flagged} flagged)` +
    (r.out_of_plane ? `; ${r.out_of_plane} out-of-plane points not drawn` : "") +
    ` · noise: ${r.noise_model}` + (view.modelNote ? ` · ${view.modelNote}` : "");
  const sides = [...new Set(view.panels.map((p) => p.side))];
  const incidences = [...new Set(view.panels.map((p) => p.theta_i_deg))].sort((a, b) => a - b);
  const grid = $("panels");
  grid.style.gridTemplateColumns = `repeat(${incidences.length}, 340px)`;
  const wanted = view.panels.map((p) => `panel-${p.key.replace(/[^A-Za-z0-9]/g, "_")}`);
  if ([...grid.children].map((c) => c.id).join() !== wanted.join()) {
    grid.innerHTML = "";
    for (const side of sides) {
      for (const ti of incidences) {
        const panel = view.panels.find((p) => p.side === side && p.theta_i_deg === ti);
        const el = document.createElementNS("http://www.w3.org/2000/svg", "svg");
        el.id = panel ? `panel-${panel.key.replace(/[^A-Za-z0-9]/g, "_")}` : `empty-${side}-${ti}`;
        el.setAttribute("class", "bsdf-panel");
        grid.appendChild(el);
      }
    }
  }
  let labels = [];
  for (const panel of view.panels) {
    const el = document.getElementById(`panel-${panel.key.replace(/[^A-Za-z0-9]/g, "_")}`);
    const mine = [...view.reduced.values()].filter((p) => p.key === panel.key);
    const curves = view.models.get(panel.key) || [];
    if (curves.length > labels.length) labels = curves.map((c) => c.label);
    const yValues = mine.filter((p) => p.valid).map((p) => p.f);
    const y = panel.y ? [Math.log10(panel.y[0]), Math.log10(panel.y[1])] : GonioPlot.logRange(yValues, [-4, 2]);
    GonioPlot.draw(el, {
      x: panel.x, y, title: `θi = ${panel.theta_i_deg}°, ${panel.side} (${panel.valid} of ${panel.points} valid)`,
      xlabel: "outgoing angle (deg, forward > 0)", ylabel: "BSDF (1/sr)",
      lines: curves.map((c, k) => ({ x: c.x, y: c.y, color: MODEL_COLOUR, dash: k ? "5 3" : null })),
      points: mine.map((p) => ({
        x: p.x, y: p.f, color: p.valid ? "#111" : "#8a8f96", hollow: !p.valid,
        ring: p.flags.includes("retried") ? RETRY_COLOUR : null,
        err: p.valid && p.s !== null ? [p.f - p.s, p.f + p.s] : null,
        tip: `reading #${p.i}: ${p.x.toFixed(2)}°, ${p.f === null ? "-" : p.f.toPrecision(4)} ± ${p.s === null ? "-" : p.s.toPrecision(2)} 1/sr${p.flags.length ? ", " + p.flags.join(", ") : ""}`,
      })),
    });
  }
  const entries = [{ kind: "point", color: "#111", label: "measured (± 1 sigma)" },
    { kind: "hollow", color: "#8a8f96", label: "flagged: dark-limited, saturated, signature, horizon" },
    { kind: "ring", color: RETRY_COLOUR, label: "retried" }];
  labels.forEach((label, k) => entries.push({ kind: "line", color: MODEL_COLOUR, dash: k ? "5 3" : null, label }));
  GonioPlot.legend($("bsdf-legend"), entries);
}

/* -- polling ----------------------------------------------------------------------------- */

async function tick(again = true) {
  try {
    const s = await getJSON("/status.json");
    view.status = s;
    renderStatus(s);
    const d = await getJSON(`/data.json?since=${view.raw.length}&version=${view.version}`);
    mergeData(d);
    renderRaw();
    renderBsdf();
  } catch (e) {
    const status = $("status");
    status.textContent = "viewer not reachable";
    status.className = "status offline";
    $("reason").textContent = e.message;
  }
  if (again) setTimeout(tick, POLL_MS);
}

// the key came in the URL; the cookie it set carries it from here: keep it off the address bar
if (location.search) history.replaceState(null, "", location.pathname);
for (const action of ["pause", "resume", "abort"]) $(action).addEventListener("click", () => control(action));
window.addEventListener("resize", () => { view.rawDirty = view.bsdfDirty = true; renderRaw(); renderBsdf(); });
tick();
