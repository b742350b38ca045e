// The sa-daemon page: renders the daemon's state (docs/protocol.md) pushed over the WebSocket of
// `sa-daemon web`, and sends the person's commands back. No framework, no build step.
"use strict";

const METHODS = ["manual", "ho", "ho+noassist", "blend", "policy", "policy+noqns", "policy+withoutnoassist",
                 "policy+noho"];
const $ = (id) => document.getElementById(id);
// Why the robot holds its assistance back although its plan would assist (the state's `yielding`).
const HELD_BACK = {near_object: "near the object, you finish the grasp", user_opposes: "you keep pushing against it",
                   mode_churn: "you keep switching mode"};
let ws = null;
let scene = null;
let last = null;           // the last state message
const latencies = [];      // s from this page's server receiving a state to its pixels
window.saLatency = latencies;
window.saRendered = 0;     // states drawn (for tests)
window.saReplies = [];     // command replies and refusals (for tests)

function send(body) {
  if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(body));
}

function connect() {
  const proto = location.protocol === "https:" ? "wss:" : "ws:";
  ws = new WebSocket(`${proto}//${location.host}/ws`);
  ws.onopen = () => setBadge($("link"), "waiting for the daemon", false);
  ws.onclose = () => { setBadge($("link"), "disconnected: retrying", false); setTimeout(connect, 1000); };
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    if (msg.type === "state") onState(msg);
    else if (msg.type === "event") onEvent(msg.event);
    else if (msg.type === "hello") { scene = msg.scene; send({cmd: "status"}); }
    else if (msg.type === "reply" || msg.type === "refused") onReply(msg);
  };
}

function setBadge(el, text, good) {
  el.textContent = text;
  el.className = "badge " + (good === undefined ? "" : good ? "ok" : "bad");
}

let lastStateAt = 0;       // performance.now() of the last state (ms)

function onState(msg) {
  last = msg.state;
  lastStateAt = performance.now();
  const rx = msg.rx_wall;
  render(last);
  // The frame that shows this state is painted after the next animation frame callback.
  requestAnimationFrame(() => requestAnimationFrame(() => {
    latencies.push(Date.now() / 1000 - rx);
    if (latencies.length > 600) latencies.shift();
    window.saRendered += 1;
  }));
}

function render(s) {
  const q = s.question;
  $("question").textContent = q ? q : "No question";
  $("yes").disabled = $("no").disabled = $("other").disabled = !q;
  $("action").textContent = s.action.kind + (s.action.goal ? ` ${s.action.goal}` : "")
    + (s.yielding ? `, held back: ${HELD_BACK[s.yielding] || s.yielding}` : "");
  $("mode").textContent = s.mode;
  $("assist").textContent = (s.assist ? "on" : "off") + `, ${s.method}`;
  const pl = s.planner;
  $("planner").textContent = `${pl.status}, last plan ${pl.last_plan_ms.toFixed(0)} ms, ${pl.restarts} restarts`;
  $("codes").textContent = s.safety_codes.length ? s.safety_codes.join(", ") : "none";
  setBadge($("safety"), `safety: ${s.safety}`, s.safety === "ok");
  $("stopped").textContent = s.stopped ? "STOPPED: press Resume to move again"
    : (s.stop_tested === false ? "Press STOP, then Resume, to test the stop before the arm moves" : "");
  if ($("method").value !== s.method) $("method").value = s.method;
  if (latencies.length) {
    const sorted = [...latencies].sort((a, b) => a - b);
    $("latency").textContent = `${(sorted[Math.floor(sorted.length / 2)] * 1000).toFixed(0)} ms to the screen`;
  }
  renderBars(s.belief);
  drawTable(s);
}

const barOf = new Map();   // goal -> its <li>, kept across states (only widths, numbers and order change)

function barFor(goal) {
  let li = barOf.get(goal);
  if (li) return li;
  li = document.createElement("li");
  li.dataset.goal = goal;
  const name = document.createElement("span");
  name.textContent = goal;
  const track = document.createElement("span");
  track.className = "track";
  track.setAttribute("role", "meter");
  track.setAttribute("aria-label", goal);
  track.setAttribute("aria-valuemin", "0");
  track.setAttribute("aria-valuemax", "1");
  const fill = document.createElement("span");
  fill.className = "fill";
  fill.style.display = "block";
  track.append(fill);
  const val = document.createElement("span");
  val.className = "p";
  li.append(name, track, val);
  barOf.set(goal, li);
  return li;
}

function renderBars(belief) {
  const ol = $("bars");
  const items = [...belief].sort((a, b) => b.p - a.p);
  items.forEach(({goal, p}, i) => {
    const li = barFor(goal);
    li.dataset.p = p.toFixed(4);
    li.children[1].setAttribute("aria-valuenow", p.toFixed(3));
    li.children[1].firstChild.style.width = `${(100 * p).toFixed(1)}%`;
    li.children[2].textContent = p.toFixed(2);
    if (ol.children[i] !== li) ol.insertBefore(li, ol.children[i] || null);
  });
}

function drawTable(s) {
  const c = $("view");
  const g = c.getContext("2d");
  g.clearRect(0, 0, c.width, c.height);
  if (!scene) return;
  // Base frame seen from above: x forward (up on the screen), y left (left on the screen), 1 px = 2 mm.
  const pts = scene.objects.map((o) => o.position).concat([s.gripper_pose ? s.gripper_pose.position : [0, 0, 0]]);
  const cx = pts.reduce((a, p) => a + p[0], 0) / pts.length, cy = pts.reduce((a, p) => a + p[1], 0) / pts.length;
  const k = 500;
  const X = (p) => c.width / 2 - (p[1] - cy) * k, Y = (p) => c.height / 2 - (p[0] - cx) * k;
  const prob = Object.fromEntries(s.belief.map(({goal, p}) => [goal, p]));
  for (const o of scene.objects) {  // box: full extents [x, y, z]; cylinder [radius, height]; sphere [radius]
    const x = X(o.position), y = Y(o.position);
    g.fillStyle = "#b9ad94";
    let reach;
    if (o.shape === "box") {
      g.save(); g.translate(x, y); g.rotate(-o.yaw);  // base x is up the screen, y to the left
      g.fillRect(-o.size[1] * k / 2, -o.size[0] * k / 2, o.size[1] * k, o.size[0] * k);
      g.restore();
      reach = 0.5 * k * Math.hypot(o.size[0], o.size[1]);
    } else {
      reach = o.size[0] * k;
      g.beginPath(); g.arc(x, y, reach, 0, 2 * Math.PI); g.fill();
    }
    g.fillStyle = "#111"; g.font = "14px system-ui"; g.fillText(o.name, x + reach + 3, y + 4);
  }
  for (const goal of scene.goals) {
    const p = prob[goal.target] || 0;
    g.fillStyle = `rgba(11, 79, 163, ${0.15 + 0.85 * Math.min(1, p * 2)})`;
    for (const pose of goal.poses) {
      g.beginPath(); g.arc(X(pose.position), Y(pose.position), 4, 0, 2 * Math.PI); g.fill();
    }
  }
  if (s.gripper_pose) {
    const p = s.gripper_pose.position;
    g.fillStyle = s.stopped ? "#a4000f" : "#f5a100";
    g.beginPath(); g.arc(X(p), Y(p), 9, 0, 2 * Math.PI); g.fill();
    g.strokeStyle = "#111"; g.lineWidth = 2; g.stroke();
  }
}

function onReply(msg) {
  window.saReplies.push(msg);
  if (msg.type === "reply" && msg.cmd === "status" && msg.ok) {
    $("other").hidden = !(msg.answers || []).includes("other");
    const sel = $("profile");
    sel.replaceChildren(...(msg.profiles || []).map((n) => { const o = document.createElement("option"); o.value = o.textContent = n; return o; }));
    if (msg.profile) sel.value = msg.profile;
    $("profile-note").textContent = msg.profile ? `in force: ${msg.profile}` : "no profile";
    $("answer-times").textContent = answerTimes(msg.answer_times);
  } else if (msg.cmd === "set_profile" || (msg.type === "refused")) {
    $("profile-note").textContent = msg.ok ? `switched to ${msg.profile}` : (msg.error || msg.reason || "");
  }
}

// How long this person takes to answer, against what the planner charges a question (status.answer_times).
function answerTimes(a) {
  if (!a || !a.count) return "";
  let tail = "";
  if (a.learning) tail = `: the planner charges ${a.charged_s} s a question, learned from them`;
  else if (a.suggested_s !== null && a.suggested_s > a.charged_s)
    tail = `: slower than the ${a.charged_s} s the planner charges; a profile could set question_time_s = ${a.suggested_s}`;
  return `Answers: ${a.count}, median ${a.median_s.toFixed(1)} s${tail}`;
}

function onEvent(e) {
  if (e.type === "answer") send({cmd: "status"});  // the answer times have changed
  const li = document.createElement("li");
  const detail = Object.entries(e).filter(([k]) => k !== "t" && k !== "type")
    .map(([k, v]) => `${k}=${typeof v === "object" ? JSON.stringify(v) : v}`).join(" ");
  li.textContent = `[${(e.t || 0).toFixed(1)} s] ${e.type} ${detail}`;
  const ol = $("events");
  ol.prepend(li);
  while (ol.children.length > 50) ol.lastChild.remove();
}

function init() {
  for (const m of METHODS) {
    const o = document.createElement("option");
    o.value = o.textContent = m;
    $("method").append(o);
  }
  $("stop").onclick = () => send({cmd: "stop"});
  $("resume").onclick = () => send({cmd: "resume"});
  $("yes").onclick = () => send({cmd: "answer", value: "yes"});
  $("no").onclick = () => send({cmd: "answer", value: "no"});
  $("other").onclick = () => send({cmd: "answer", value: "other"});
  $("method").onchange = (e) => send({cmd: "set_method", method: e.target.value});
  $("switch").onclick = () => { if ($("profile").value) send({cmd: "set_profile", profile: $("profile").value}); };
  document.addEventListener("keydown", (e) => {
    if (e.target.tagName === "SELECT" || e.ctrlKey || e.metaKey || e.altKey) return;
    const key = e.key.toLowerCase();
    if (key === "s" || key === "escape") $("stop").click();
    else if (key === "r") $("resume").click();
    else if (key === "y" && !$("yes").disabled) $("yes").click();
    else if (key === "n" && !$("no").disabled) $("no").click();
    else if (key === "o" && !$("other").hidden && !$("other").disabled) $("other").click();
  });
  connect();
  // The view is only as good as its last state: say so when the daemon goes quiet.
  setInterval(() => {
    if (!ws || ws.readyState !== WebSocket.OPEN) return;
    const age = (performance.now() - lastStateAt) / 1000;
    if (lastStateAt === 0) setBadge($("link"), "waiting for the daemon", false);
    else if (age > 1.0) setBadge($("link"), `no state for ${age.toFixed(0)} s: the view is stale`, false);
    else setBadge($("link"), "live", true);
  }, 250);
}

init();
