// embodied-adhoc live page: overhead view, keyboard walking, the robot's question, typed or spoken replies.
// No external assets. window.liveStats keeps what the page measured (read by the tests and shown below the view).
"use strict";

const KEYS = {
  ArrowUp: "up", KeyW: "up", ArrowDown: "down", KeyS: "down",
  ArrowLeft: "left", KeyA: "left", ArrowRight: "right", KeyD: "right",
};
const ACT_KEYS = new Set(["KeyE", "Space"]);
const stats = { frameIntervals: [], keyToMotion: [], frames: 0, states: 0, heard: [], errors: [], steps: [],
                posterior: null, lastState: null, questions: 0, done: null, outcomes: [] };
window.liveStats = stats;

const $ = (id) => document.getElementById(id);
const held = new Set();
let socket = null, seq = 0, tasks = [], lastFrameAt = null, frameUrl = null;
let pendingMotion = null, motionSeen = false, recorder = null, questionStep = null;

function token() { return new URLSearchParams(location.search).get("token") || ""; }

function ping() { send({ type: "ping", t: performance.now() }); }
setInterval(ping, 5000);  // the server frees the slot of a page silent for its idle timeout

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const query = token() ? "?token=" + encodeURIComponent(token()) : "";
  socket = new WebSocket(`${scheme}://${location.host}/ws${query}`);
  socket.binaryType = "arraybuffer";
  socket.onopen = () => { $("connection").textContent = "connected"; $("connection").className = "good"; };
  socket.onclose = () => {
    $("connection").textContent = "disconnected: reconnecting…"; $("connection").className = "bad";
    setTimeout(connect, 2000);
  };
  socket.onmessage = (message) => {
    if (typeof message.data === "string") onEvent(JSON.parse(message.data));
    else onBinary(new Uint8Array(message.data));
  };
}

function send(object) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(object));
}

function log(text) {
  const item = document.createElement("li");
  item.textContent = text;
  $("log").prepend(item);
}

function onBinary(bytes) {
  const tag = String.fromCharCode(bytes[0]);
  const body = bytes.subarray(1);
  if (tag === "F") {
    const now = performance.now();
    if (lastFrameAt !== null) stats.frameIntervals.push(now - lastFrameAt);
    lastFrameAt = now;
    stats.frames += 1;
    const url = URL.createObjectURL(new Blob([body], { type: "image/jpeg" }));
    $("view").src = url;
    if (frameUrl) URL.revokeObjectURL(frameUrl);
    frameUrl = url;
    if (pendingMotion && motionSeen) {  // this frame shows the first motion after the key press
      stats.keyToMotion.push(now - pendingMotion.t0);
      pendingMotion = null; motionSeen = false;
    }
    showLatency();
  } else if (tag === "A") {
    const audio = new Audio(URL.createObjectURL(new Blob([body], { type: "audio/wav" })));
    audio.play().catch(() => log("(the browser blocked the robot's voice: click the page once)"));
  }
}

function summary(values) {
  if (!values.length) return "—";
  const sorted = [...values].sort((a, b) => a - b);
  const mean = values.reduce((a, b) => a + b, 0) / values.length;
  const p95 = sorted[Math.min(sorted.length - 1, Math.floor(0.95 * sorted.length))];
  return `${mean.toFixed(0)} ms mean, ${p95.toFixed(0)} ms p95 (n=${values.length})`;
}

function showLatency() {
  $("frame-interval").textContent = summary(stats.frameIntervals.slice(-300));
  $("key-motion").textContent = summary(stats.keyToMotion);
}

function onEvent(event) {
  switch (event.type) {
    case "hello":
      tasks = event.tasks;
      $("participant").textContent = `participant ${event.participant}`;
      if (event.started) $("start").disabled = true;
      offerPlaces(event.places || []);
      stats.done = null;
      $("end").hidden = true;
      $("start").disabled = !!event.started;
      restore(event.restore);
      showStudy(event.study);
      break;
    case "study_complete":
      stats.studyComplete = true;
      $("survey").replaceChildren();
      $("end-text").textContent = "The study is complete. Thank you for taking part!";
      log("study complete");
      break;
    case "outcome":
      stats.outcomes.push(event);
      $("notice").textContent = event.result;
      log(`${event.kind} ball ${event.ball}: ${event.succeeded ? "done" : "failed"} (${event.result})`);
      break;
    case "state": onState(event); break;
    case "starting": $("start").disabled = true; log("episode started"); break;
    case "started": showBelief(event.posterior); break;
    case "question":
      stats.questions += 1;
      questionStep = event.step;
      $("heard").textContent = "";
      openQuestion(event.text);
      log(`step ${event.step}: robot asks "${event.text}"`);
      break;
    case "heard":
      stats.heard.push(event);
      $("heard").textContent = (event.transcript !== undefined ? `recognised "${event.transcript}" → ` : "") +
        (event.node === null ? "no location heard" : `heard: node ${event.node} (${event.place})`);
      log($("heard").textContent);
      closeQuestion();
      break;
    case "step":
      stats.steps.push(event);
      if (event.step === questionStep) closeQuestion();  // answered, or the robot stopped waiting
      showBelief(event.posterior);
      log(`step ${event.step}: ${event.action}; ${event.observation}`);
      break;
    case "done":
      stats.done = event;
      $("notice").textContent = `episode over: ${event.outcome} after ${event.steps} steps. Thank you!`;
      $("end").hidden = false;
      $("end-text").textContent = event.outcome === "success"
        ? `All three balls are in the robot's container: done in ${event.sim_time} s and ${event.steps} robot decisions.`
        : `The episode ended (${event.outcome}) after ${event.steps} robot decisions.`;
      closeQuestion();
      if (study) showSurvey();
      log(`done: ${event.outcome}`);
      break;
    case "error":
      stats.errors.push(event.message);
      $("notice").textContent = event.message;
      break;
    default: break;
  }
}

function onState(state) {
  stats.states += 1;
  const previous = stats.lastState;
  stats.lastState = state;
  if (pendingMotion && state.ack >= pendingMotion.seq && previous) {
    const [x0, y0] = pendingMotion.xy;
    if (Math.hypot(state.human[0] - x0, state.human[1] - y0) > 0.01) motionSeen = true;
  }
  $("sim-time").textContent = `${state.sim_time.toFixed(1)} s`;
  $("you").textContent = `area ${state.human_node}` + (state.holding !== null ? `, holding ball ${state.holding}` : "") +
    (state.busy ? " (busy)" : "");
  const names = ["on the floor", "held", "in the container"];
  $("balls").textContent = state.balls.map((s, i) => `${i}: ${names[s]}`).join(", ");
  $("robot").textContent = state.action ? `step ${state.step}: ${state.action}` : "—";
  if (state.notice && !stats.done) $("notice").textContent = state.notice;
  if (state.posterior) showBelief(state.posterior);
  if (state.question_open && $("question-panel").className !== "asking") openQuestion("Where are you?");
  if (!state.question_open && $("question-panel").className === "asking") closeQuestion();
}

let study = null;
function showStudy(info) {  // a study: the instructions before each episode, the questionnaire after it
  study = info;
  $("study").hidden = !info;
  if (!info) return;
  $("study-position").textContent = `episode ${info.position} of ${info.of}`;
  $("instructions").textContent = info.instructions;
  $("survey").replaceChildren();
  stats.studyPosition = info.position;
}

function showSurvey() {
  const form = document.createElement("form");
  form.id = "survey-form";
  for (const item of study.questionnaire) {
    const field = document.createElement("fieldset"), legend = document.createElement("legend");
    legend.textContent = item.text;
    field.append(legend, "disagree ");
    for (let value = 1; value <= item.scale; value++) {
      const label = document.createElement("label"), input = document.createElement("input");
      input.type = "radio"; input.name = item.id; input.value = String(value); input.id = `${item.id}-${value}`;
      label.append(input, String(value));
      field.append(label);
    }
    field.append(" agree");
    form.append(field);
  }
  const submit = document.createElement("button");
  submit.type = "submit"; submit.id = "survey-send"; submit.textContent = "Send and continue";
  form.append(submit);
  form.addEventListener("submit", (event) => {
    event.preventDefault();
    const answers = {};
    for (const item of study.questionnaire) {
      const chosen = form.querySelector(`input[name="${item.id}"]:checked`);
      if (!chosen) { $("notice").textContent = `please answer: ${item.text}`; return; }
      answers[item.id] = Number(chosen.value);
    }
    send({ type: "questionnaire", answers });
    submit.disabled = true;
  });
  $("survey").replaceChildren(form);
}

function offerPlaces(places) {  // the names the recogniser understands, as on the map
  const list = $("places"), buttons = $("place-buttons");
  list.replaceChildren(...places.map((p) => { const o = document.createElement("option"); o.value = `I'm at the ${p}`; return o; }));
  buttons.replaceChildren(...places.map((p) => {
    const b = document.createElement("button");
    b.type = "button"; b.textContent = p; b.className = "place";
    b.addEventListener("click", () => { $("reply-text").value = `I'm at the ${p}`; $("reply-text").focus(); });
    return b;
  }));
}

function restore(snapshot) {  // a page that (re)connects shows the session as it is
  if (!snapshot) return;
  $("log").replaceChildren();
  for (const event of snapshot.history) {
    if (event.type === "question") { log(`step ${event.step}: robot asks "${event.text}"`); stats.questions += 1; }
    else if (event.type === "step") log(`step ${event.step}: ${event.action}; ${event.observation}`);
    else if (event.type === "outcome") log(`${event.kind} ball ${event.ball}: ${event.succeeded ? "done" : "failed"} (${event.result})`);
    else if (event.type === "done") onEvent(event);
  }
  if (snapshot.posterior) showBelief(snapshot.posterior);
  if (snapshot.state) onState(snapshot.state);
}

function openQuestion(text) {
  $("question").textContent = text;
  $("question-panel").className = "asking";
  for (const id of ["reply-text", "reply-send", "mic"]) $(id).disabled = false;
}

function closeQuestion() {
  $("question-panel").className = "idle";
  for (const id of ["reply-text", "reply-send", "mic"]) $(id).disabled = true;
}

function showBelief(posterior) {
  if (!posterior) return;
  stats.posterior = posterior;
  const rows = posterior.map((p, k) => {
    const row = document.createElement("div"), label = document.createElement("span");
    const fill = document.createElement("span"), value = document.createElement("span");
    row.className = "bar"; fill.className = "fill";
    label.textContent = `task [${tasks[k] ? tasks[k].join(",") : k}]`;
    fill.style.width = `${Math.round(240 * p)}px`;  // CSSOM, allowed by the page's content security policy
    value.textContent = p.toFixed(2);
    row.append(label, fill, value);
    return row;
  });
  $("belief").replaceChildren(...rows);
}

function keysChanged(added) {
  seq += 1;
  if (added && stats.lastState) { pendingMotion = { seq, t0: performance.now(), xy: stats.lastState.human }; motionSeen = false; }
  send({ type: "keys", held: [...held], seq });
}

document.addEventListener("keydown", (event) => {
  if (event.target instanceof HTMLInputElement) return;  // typing a reply
  const direction = KEYS[event.code];
  if (direction) {
    event.preventDefault();
    if (event.repeat || held.has(direction)) return;
    held.add(direction);
    keysChanged(true);
  } else if (ACT_KEYS.has(event.code)) {
    event.preventDefault();
    if (!event.repeat) { seq += 1; send({ type: "act", seq }); }
  }
});
document.addEventListener("keyup", (event) => {
  const direction = KEYS[event.code];
  if (direction && held.delete(direction)) keysChanged(false);
});
window.addEventListener("blur", () => { if (held.size) { held.clear(); keysChanged(false); } });

$("start").addEventListener("click", () => send({ type: "start" }));
$("reply-form").addEventListener("submit", (event) => {
  event.preventDefault();
  const text = $("reply-text").value.trim();
  if (!text) return;
  seq += 1;
  send({ type: "reply", text, seq });
  log(`you typed "${text}"`);
  $("reply-text").value = "";
  $("reply-text").blur();
});

// Spoken replies: raw samples from the microphone, 16 kHz 16-bit mono WAV, sent as one binary message.
$("mic").addEventListener("click", async () => {
  if (recorder) { finishRecording(); return; }
  try {
    const stream = await navigator.mediaDevices.getUserMedia({ audio: true });
    const context = new AudioContext();
    const source = context.createMediaStreamSource(stream);
    const processor = context.createScriptProcessor(4096, 1, 1);
    const chunks = [];
    processor.onaudioprocess = (e) => chunks.push(new Float32Array(e.inputBuffer.getChannelData(0)));
    source.connect(processor); processor.connect(context.destination);
    recorder = { stream, context, processor, chunks, timer: setTimeout(finishRecording, 10000) };
    $("mic").classList.add("recording"); $("mic").textContent = "Stop & send";
  } catch (error) {
    $("notice").textContent = `microphone unavailable (${error.name}): type your reply instead`;
  }
});

function finishRecording() {
  const { stream, context, processor, chunks, timer } = recorder;
  recorder = null;
  clearTimeout(timer);
  processor.disconnect(); stream.getTracks().forEach((t) => t.stop());
  $("mic").classList.remove("recording"); $("mic").textContent = "Speak";
  const rate = context.sampleRate;
  context.close();
  const samples = downsample(concat(chunks), rate, 16000);
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(wav(samples, 16000));
  log(`you spoke (${(samples.length / 16000).toFixed(1)} s): recognising…`);
}

function concat(chunks) {
  const out = new Float32Array(chunks.reduce((n, c) => n + c.length, 0));
  let offset = 0;
  for (const c of chunks) { out.set(c, offset); offset += c.length; }
  return out;
}

function downsample(samples, from, to) {  // average over each output sample's span (a box low-pass)
  if (from === to) return samples;
  const ratio = from / to, out = new Float32Array(Math.floor(samples.length / ratio));
  for (let i = 0; i < out.length; i++) {
    const start = Math.floor(i * ratio), end = Math.min(samples.length, Math.floor((i + 1) * ratio));
    let sum = 0;
    for (let j = start; j < end; j++) sum += samples[j];
    out[i] = sum / Math.max(1, end - start);
  }
  return out;
}

function wav(samples, rate) {
  const buffer = new ArrayBuffer(44 + samples.length * 2), view = new DataView(buffer);
  const text = (offset, s) => { for (let i = 0; i < s.length; i++) view.setUint8(offset + i, s.charCodeAt(i)); };
  text(0, "RIFF"); view.setUint32(4, 36 + samples.length * 2, true); text(8, "WAVE"); text(12, "fmt ");
  view.setUint32(16, 16, true); view.setUint16(20, 1, true); view.setUint16(22, 1, true);
  view.setUint32(24, rate, true); view.setUint32(28, rate * 2, true); view.setUint16(32, 2, true);
  view.setUint16(34, 16, true); text(36, "data"); view.setUint32(40, samples.length * 2, true);
  for (let i = 0; i < samples.length; i++) {
    const s = Math.max(-1, Math.min(1, samples[i]));
    view.setInt16(44 + 2 * i, s < 0 ? s * 0x8000 : s * 0x7fff, true);
  }
  return buffer;
}

connect();
