// The status page: polls /api/status and draws it. Everything here is served by the
// certifier itself; nothing is loaded from elsewhere.
"use strict";
const POLL_MS = 500;
const $ = (id) => document.getElementById(id);
const num = (v, d = 4) => (v === null || v === undefined ? "none" : Number(v).toPrecision(d));

function text(id, value) {
  const el = $(id);
  if (el.textContent !== value) el.textContent = value;
}

function gate(s) {
  const box = $("gate-box");
  let state = s.open ? "open" : "closed";
  if (s.ended) state = "ended";
  box.className = "gate " + state;
  document.body.dataset.gate = s.open ? "open" : "closed";
  text("gate", s.ended ? "ended" : state);
  // The server writes the time as a person reads it: UTC for Unix seconds, else seconds.
  const since = s.since_text === null ? "" : /Z$/.test(s.since_text)
    ? "since " + s.since_text : "since t = " + s.since_text + " s";
  if (s.ended) {
    text("gate-words", "The run ended: " + s.ended + ". Nothing is vouched for after its last sample.");
  } else if (s.open) {
    text("gate-words", "CERTIFIED: the candidate may be deployed (" + s.certificate + " certificate" +
      (s.orders.length > 0 ? " of order " + s.look_order + ", chosen from the data" :
        s.order === null || s.order === 1 ? "" : " of order " + s.order) +
      (s.risk === null ? ", no stated risk" : ", risk " + s.risk + " over the run") + ").");
  } else {
    text("gate-words", "NOT CERTIFIED: do not deploy the candidate.");
  }
  text("since", since);
}

function stall(s) {
  const stalled = !!s.stalled;
  document.body.dataset.stalled = String(stalled);
  $("stall").hidden = !stalled;
  if (stalled) {
    text("stall-words", "no sample for " + num(s.age_seconds, 3) + " s (more than " +
      s.stale_after_seconds + " s): the source has stalled; the gate shown is the last one computed.");
  }
}

function chart(s) {
  const svg = $("chart");
  const W = 800, H = 260, L = 60, R = 10, T = 10, B = 30;
  const pts = s.chart.filter((p) => p[1] !== null);
  const all = s.chart;
  if (all.length === 0) { svg.innerHTML = ""; return; }
  const t0 = all[0][0], t1 = Math.max(all[all.length - 1][0], t0 + 1e-9);
  const values = pts.map((p) => p[1]).concat([s.margin]);
  let lo = Math.min(...values), hi = Math.max(...values);
  if (hi - lo < 1e-12) { lo -= 1; hi += 1; }
  const pad = (hi - lo) * 0.08; lo -= pad; hi += pad;
  const x = (t) => L + ((t - t0) / (t1 - t0)) * (W - L - R);
  const y = (v) => T + (1 - (v - lo) / (hi - lo)) * (H - T - B);
  let out = "";
  for (let i = 0; i < all.length; i++) {
    if (!all[i][2]) continue;
    const next = i + 1 < all.length ? all[i + 1][0] : all[i][0];
    out += `<rect x="${x(all[i][0])}" y="${T}" width="${Math.max(x(next) - x(all[i][0]), 1)}" height="${H - T - B}" fill="rgba(26,127,55,0.18)"/>`;
  }
  out += `<line x1="${L}" x2="${W - R}" y1="${y(s.margin)}" y2="${y(s.margin)}" stroke="#b42318" stroke-width="2" stroke-dasharray="6 4"/>`;
  let path = "", pen = "M";
  for (const p of all) {
    if (p[1] === null) { pen = "M"; continue; }
    path += `${pen}${x(p[0]).toFixed(1)},${y(p[1]).toFixed(1)} `;
    pen = "L";
  }
  out += `<path d="${path}" fill="none" stroke="#0969da" stroke-width="2"/>`;
  out += `<text x="4" y="${T + 10}" font-size="12">${num(hi, 3)}</text>`;
  out += `<text x="4" y="${H - B}" font-size="12">${num(lo, 3)}</text>`;
  out += `<text x="${L}" y="${H - 8}" font-size="12">t = ${num(t0, 6)} s</text>`;
  out += `<text x="${W - R - 120}" y="${H - 8}" font-size="12">t = ${num(t1, 6)} s</text>`;
  svg.innerHTML = out;
}

function counters(s) {
  const c = s.counters;
  const rows = [["samples", c.samples], ["gaps", c.gaps], ["skipped rows", c.skipped],
    ["bad payloads", c.bad], ["reconnects", c.reconnects], ["late messages", c.late]];
  if (s.kind === "network") rows.splice(1, 0, ["epochs", c.epochs]);
  rows.push(["last sample", s.t === null ? "none" : "t = " + num(s.t, 8) + " s"]);
  rows.push(["age of the last sample", s.age_seconds === null ? "none" : num(s.age_seconds, 3) + " s"]);
  $("counters").tBodies[0].innerHTML = rows.map((r) => `<tr><td>${r[0]}</td><td class="num">${r[1]}</td></tr>`).join("");
  text("source", s.source || "");
}

function subsystems(s) {
  $("subsystems-box").hidden = s.subsystems.length === 0;
  const esc = (v) => String(v).replace(/[&<>"]/g, (ch) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" }[ch]));
  $("subsystems").tBodies[0].innerHTML = s.subsystems.map((u) =>
    `<tr><td>${esc(u.name)}</td><td class="num">${num(u.certificate)}</td>` +
    `<td class="${u.open ? "yes" : "no"}">${u.open ? "certified" : "not certified"}</td>` +
    `<td>${esc(u.reason || "")}</td></tr>`).join("");
}

function draw(s) {
  text("name", s.name);
  text("kind", s.kind === "network" ? "network" : "loop");
  document.title = (s.open ? "OPEN" : "CLOSED") + " · " + s.name + " · streamcert";
  // The loop model's order: 1 is the paper's first-order model; 2 and 3 read a closed loop of
  // that order through one output.
  const order = s.orders.length > 0
    ? " with the loop model's order chosen from the data (orders " + s.orders.join(", ") +
      " side by side, each at risk δ/" + s.orders.length + ")"
    : s.order === null ? "" : " with a loop model of order " + s.order;
  text("candidate", "Candidate judged at the margin " + s.margin + " /s" + order +
    "; deciding certificate: " + s.certificate + ".");
  gate(s);
  stall(s);
  text("reason", s.reason ? s.reason.words : "none: the gate is open");
  text("detail", s.reason ? s.reason.detail : "");
  text("verdict", s.verdict);
  chart(s);
  counters(s);
  subsystems(s);
  text("updated", "updated " + new Date().toLocaleTimeString());
}

async function poll() {
  try {
    const r = await fetch("/api/status", { cache: "no-store" });
    if (r.ok) draw(await r.json());
    else text("updated", "the server answered " + r.status);
  } catch (e) {
    text("updated", "the certifier does not answer (" + e + ")");
    document.body.dataset.gate = "unknown";
  }
  setTimeout(poll, POLL_MS);
}
poll();
