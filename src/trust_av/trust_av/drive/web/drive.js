// trust-av drive: the participant's page. Plain JS, no build step, nothing fetched from
// elsewhere: the view is drawn by view.js with the vendored Konva (vendor/README.md). State
// frames arrive over the WebSocket (a few per control period); the view is drawn at the
// display's frame rate, interpolating the frames RENDER_DELAY_MS behind the newest one (and
// not drawn again while that would show the same, as between drives). A
// pedal sample is sent at once on a key or pointer press or release, on any other change of
// the pedal at most once per control period, and at the control rate while nothing changes,
// all within the server's rate limit (a token bucket of inputBurst samples refilled at the
// control rate on the page's own clock: each sample carries its send time, t_ms, the
// performance.now() the page's bucket used): the page keeps its own, smaller bucket,
// refilled a little slower, and one sample of it for a press or release, so the server
// refuses none, however the samples arrive. The server acknowledges samples in its frames;
// the page echoes each acknowledgement at once: the server measures the latency on its own
// clock (the page's time serves the rate limit only).
'use strict';

const RENDER_DELAY_MS = 100;
const VEHICLE_LENGTH_M = 4.5;
const KEY_GAS_PER_S = 1.5, KEY_BRAKE_PER_S = 2.5, KEY_RELEASE_PER_S = 4.0, KEY_STEP = 0.15;
const KEYS = ['ArrowUp', 'ArrowDown', 'KeyW', 'KeyS'];
const BUCKET_REFILL_SHARE = 0.9;       // of the control rate: a margin for network jitter
const PAGE_BURST = 3;                  // the page's bucket (the server's is larger: hello)

const drive = {
  phase: 'connecting', controlRateHz: 10, inputBurst: 4, accelMax: 2.5, accelMin: -6.0, onCollision: 'continue',
  frames: [], displayed: null, pedal: 0, seq: 0, durationS: 0, keys: new Set(),
  pointerPedal: null, prompt: null, ws: null, inputTimer: null, source: 'none',
  controlling: false, final: false, lastSentMs: -1e9, lastSentPedal: null, acks: 0, frameTimes: [], drove: false, drawnKey: null,
  tokens: 3, tokensAt: 0, pressWaiting: false, heldBack: 0,
  token: document.querySelector('meta[name="drive-token"]').content,
};
window.drive = drive;

const $ = (id) => document.getElementById(id);
const view = window.DriveView.create($('road'));
drive.view = view;                     // the Konva stage and its layers (tests, screenshots)

function connect() {
  if (drive.final) return;
  const ws = new WebSocket(`ws://${location.host}/ws?token=${encodeURIComponent(drive.token)}`);
  drive.ws = ws;
  ws.onopen = () => setStatus('connected');
  ws.onmessage = (event) => onMessage(JSON.parse(event.data));
  ws.onclose = () => {
    stopInput();
    if (drive.final) return;                // the end screen stays as it is
    setStatus('connection lost: reconnecting…');
    setTimeout(connect, 1000);
  };
}

function send(message) {
  if (drive.ws && drive.ws.readyState === WebSocket.OPEN) drive.ws.send(JSON.stringify(message));
}

function setStatus(text) { $('status').textContent = text; }

function onMessage(msg) {
  if (msg.type === 'hello') {
    drive.controlRateHz = msg.control_rate_hz;
    if (Number.isInteger(msg.input_burst) && msg.input_burst > 1) drive.inputBurst = msg.input_burst;
    drive.accelMax = msg.accel_max_mps2;
    drive.accelMin = msg.accel_min_mps2;
    drive.onCollision = msg.on_collision || 'continue';
    drive.ratingMode = msg.rating_mode === 'continuous' ? 'continuous' : 'prompt';
    drive.scale = typeof msg.scale === 'number' ? msg.scale : null;
    if (msg.phase) setPhase(msg);
    if (msg.prompts && msg.prompts.length && drive.phase === 'driving') showRating(msg.prompts[msg.prompts.length - 1]);
  } else if (msg.type === 'control') {
    setControl(msg);
  } else if (msg.type === 'phase') {
    if (msg.phase === 'ready') drive.scale = null;   // a new drive: its scale starts unset
    setPhase(msg);
  } else if (msg.type === 'rate') {
    if (drive.controlling && ['driving', 'wait'].includes(drive.phase)) showRating(msg.id);
  } else if (msg.type === 'state') {
    if (msg.ack !== undefined && drive.controlling) { send({type: 'ack', seq: msg.ack}); drive.acks++; }
    msg.received_ms = performance.now();
    drive.frameTimes.push(msg.received_ms);      // when frames came (tests, benchmark)
    if (drive.frameTimes.length > 3000) drive.frameTimes.shift();
    drive.frames.push(msg);
    if (drive.frames.length > 50) drive.frames.shift();
    showCrash(msg);
  }
}

function setControl(msg) {
  if (!msg.controlling && !msg.other && drive.drove) {
    send({type: 'take_over'});               // this tab drove: it takes the free control back
    return;
  }
  drive.controlling = msg.controlling;
  if (msg.controlling) drive.drove = true;
  else if (msg.taken_over) drive.drove = false;   // another tab took over: not taken back
  $('control').hidden = msg.controlling;
  $('control-text').textContent = msg.other
    ? 'Another tab is driving this session. Only one tab can drive.'
    : 'No tab is driving this session.';
  if (!msg.controlling) { stopInput(); hideRating(); return; }
  if (drive.phase === 'driving') startInput();
  if (continuous() && SCALE_PHASES.includes(drive.phase)) showScale(drive.scale);
}
$('take-over').addEventListener('click', () => send({type: 'take_over'}));

function setPhase(msg) {
  drive.phase = msg.phase;
  $('intro').hidden = true;
  $('questionnaire').hidden = true;
  $('message').hidden = true;
  if (msg.phase === 'ready') {
    const title = msg.practice ? 'Practice drive'
      : (msg.number ? `Drive ${msg.number} of ${msg.of}` : 'Drive');
    $('title').textContent = title;
    $('intro-title').textContent = title;
    drive.durationS = msg.duration_s;
    $('intro-length').textContent = `This ${msg.practice ? 'practice drive' : 'drive'} takes about ${Math.round(msg.duration_s)} s.`
      + (msg.practice ? ' It is for getting used to the car: nothing you do here counts.' : '');
    $('start').textContent = msg.practice ? 'Start the practice drive' : 'Start the drive';
    $('intro').hidden = false;
    if (continuous()) showScale(drive.scale);
    drive.frames = [];
    setStatus('ready');
  } else if (msg.phase === 'driving') {
    drive.durationS = msg.duration_s;
    if (drive.controlling) startInput();
    if (continuous()) showScale(drive.scale);
    setStatus('driving');
  } else if (msg.phase === 'questionnaire') {
    stopInput();
    showQuestionnaire(msg.items);
    setStatus('questionnaire');
  } else {
    stopInput();
    $('message').hidden = false;
    $('message').textContent = {
      finished: 'Thank you: the session is complete. You can close this tab.',
      wait: msg.ended_by === 'collision'
        ? 'The drive ended: your car hit the AV. Please wait a moment.'
        : 'Drive complete. Please wait a moment.',
    }[msg.phase] || 'The session is paused. When the experimenter resumes it, reload this page.';
    setStatus(msg.phase);
    if (msg.phase === 'finished' || msg.phase === 'paused') {
      drive.final = true;                   // nothing more comes: the end screen is final
      $('hud').hidden = true; $('controls').hidden = true; $('stage').hidden = true;
      if (drive.ws) drive.ws.close();
    }
  }
  if (!(continuous() ? SCALE_PHASES : ['driving', 'wait']).includes(msg.phase)) hideRating();
  if (msg.phase !== 'driving') $('crash').hidden = true;
}

function showCrash(frame) {
  $('crash').hidden = !frame.crash || drive.phase !== 'driving';
  if (frame.crash) {
    $('crash-text').textContent = drive.onCollision === 'end'
      ? 'Your car hit the AV and stopped. This drive ends here.'
      : 'Your car hit the AV and stopped behind it. Drive on when the AV moves away.';
  }
}

// ---- input -------------------------------------------------------------------------------
function gamepadPedal() {
  const pads = navigator.getGamepads ? Array.from(navigator.getGamepads()).filter(Boolean) : [];
  if (!pads.length) return null;
  const pad = pads[0];
  const gas = pad.buttons[7] ? pad.buttons[7].value : 0;
  const brake = pad.buttons[6] ? pad.buttons[6].value : 0;
  const axis = pad.axes.length > 1 ? -pad.axes[1] : 0;   // stick or wheel pedal axis
  return Math.abs(gas - brake) > 0.02 ? gas - brake : (Math.abs(axis) > 0.05 ? axis : 0);
}

let lastKeyMs = performance.now();
function updatePedal(nowMs) {
  const dt = Math.max(0, Math.min(0.1, (nowMs - lastKeyMs) / 1000));
  lastKeyMs = nowMs;
  if (drive.pointerPedal !== null) { drive.pedal = drive.pointerPedal; drive.source = 'pointer'; return; }
  const pad = gamepadPedal();
  if (pad !== null && pad !== 0) { drive.pedal = pad; drive.source = 'gamepad'; return; }
  const gas = drive.keys.has('ArrowUp') || drive.keys.has('KeyW');
  const brake = drive.keys.has('ArrowDown') || drive.keys.has('KeyS');
  let p = drive.pedal;
  if (gas && !brake) p = Math.min(1, Math.max(KEY_STEP, p + KEY_GAS_PER_S * dt));
  else if (brake && !gas) p = Math.max(-1, Math.min(-KEY_STEP, p - KEY_BRAKE_PER_S * dt));
  else p = p > 0 ? Math.max(0, p - KEY_RELEASE_PER_S * dt) : Math.min(0, p + KEY_RELEASE_PER_S * dt);
  drive.pedal = p;
  drive.source = 'keyboard';
}

function pedalAccel(p) { return p >= 0 ? p * drive.accelMax : -p * drive.accelMin; }

// The page's side of the server's rate limit: PAGE_BURST samples at once (fewer than the
// server's inputBurst), refilled at BUCKET_REFILL_SHARE of the control rate; a periodic or
// ramp sample leaves one for a press.
// A time earlier than one already counted (a frame's timestamp is its start, before an
// input event of that frame) refills nothing, as on the server.
function tokens(nowMs) {
  const most = Math.min(PAGE_BURST, drive.inputBurst - 1);
  drive.tokens = Math.min(most, drive.tokens
    + Math.max(0, nowMs - drive.tokensAt) / 1000 * BUCKET_REFILL_SHARE * drive.controlRateHz);
  drive.tokensAt = Math.max(drive.tokensAt, nowMs);
  return drive.tokens;
}

// A pedal sample now; press: a key or pointer press or release (sent as soon as the bucket
// allows: at once unless several come within a control period).
function sendSample(nowMs, press = false) {
  if (drive.inputTimer === null) return;
  updatePedal(nowMs);
  if (tokens(nowMs) < (press || drive.pressWaiting ? 1 : 2)) {
    if (press) { drive.pressWaiting = true; drive.heldBack++; }
    return;
  }
  drive.tokens -= 1;
  drive.pressWaiting = false;
  drive.lastSentMs = nowMs;
  drive.lastSentPedal = drive.pedal;
  send({type: 'input', seq: ++drive.seq, accel_mps2: pedalAccel(drive.pedal), t_ms: nowMs});
}
const periodMs = () => 1000 / drive.controlRateHz;

window.addEventListener('keydown', (e) => {
  if (!KEYS.includes(e.code)) return;
  e.preventDefault();
  if (drive.keys.has(e.code)) return;        // auto-repeat: the ramp goes on by itself
  drive.keys.add(e.code);
  sendSample(performance.now(), true);       // a press is sent at once
});
window.addEventListener('keyup', (e) => {
  if (drive.keys.delete(e.code)) sendSample(performance.now(), true);
});
window.addEventListener('blur', () => drive.keys.clear());

const pedalEl = $('pedal');
function pointerValue(e) {
  const r = pedalEl.getBoundingClientRect();
  return Math.max(-1, Math.min(1, 1 - 2 * (e.clientY - r.top) / r.height));
}
pedalEl.addEventListener('pointerdown', (e) => {
  pedalEl.setPointerCapture(e.pointerId); drive.pointerPedal = pointerValue(e); e.preventDefault();
  sendSample(performance.now(), true);
});
pedalEl.addEventListener('pointermove', (e) => { if (drive.pointerPedal !== null) drive.pointerPedal = pointerValue(e); });
const releasePointer = () => { drive.pointerPedal = null; drive.pedal = 0; sendSample(performance.now(), true); };
pedalEl.addEventListener('pointerup', releasePointer);
pedalEl.addEventListener('pointercancel', releasePointer);

function startInput() {
  if (drive.inputTimer !== null) return;
  drive.inputTimer = setInterval(() => {     // the control rate while nothing else is sent
    const now = performance.now();
    if (now - drive.lastSentMs >= 0.8 * periodMs()) sendSample(now);
  }, periodMs() / 2);
}

function stopInput() {
  if (drive.inputTimer !== null) clearInterval(drive.inputTimer);
  drive.inputTimer = null;
}

$('start').addEventListener('click', () => {
  if (continuous() && $('rating-slider').classList.contains('unset')) return;   // set it first
  $('intro').hidden = true;
  send({type: 'ready'});
});

// ---- trust rating (non-blocking, asked by the server) ----------------------------------------
function showRating(id) {
  if (drive.prompt === id) return;
  drive.prompt = id;
  $('rating-slider').value = 50;
  $('rating-slider').classList.add('unset');
  $('rating-value').textContent = 'click the scale';
  $('rating-submit').disabled = true;
  $('rating').hidden = false;
}
function hideRating() { $('rating').hidden = true; drive.prompt = null; }

// The continuous rating (the study's rating_mode): the scale stays on screen from the start
// screen (where it must be set before Start) to the drive's end; each move is sent as a
// 'trust' message, at most every TRUST_SEND_MS and the last position always, and the drive
// records its position every rating period. Its first position of a drive is the
// participant's own: it starts unset (no thumb) on every start screen.
const TRUST_SEND_MS = 200;
const SCALE_PHASES = ['ready', 'driving'];   // the phases the continuous scale is on screen
function continuous() { return drive.ratingMode === 'continuous'; }
function showScale(value) {
  const r = $('rating');
  r.classList.add('continuous');
  $('rating-submit').hidden = true;
  $('rating-question').textContent = 'How much do you trust the automated vehicle (AV) right now? '
    + 'Move the scale whenever that changes.';
  $('intro-rating').textContent = 'Set the scale below to how much you trust the AV now, then start. '
    + 'It stays on screen while you drive: move it whenever your trust in the AV changes, and keep driving.';
  if (drive.phase === 'ready') {
    $('intro').insertBefore(r, $('start'));
    if (value === null) {
      $('rating-slider').value = 50;
      $('rating-slider').classList.add('unset');
      $('rating-value').textContent = 'click the scale';
    }
  } else if (r.parentElement !== $('stage')) {
    $('stage').appendChild(r);
  }
  if (value !== null) { $('rating-slider').value = value; rated(); }
  $('start').disabled = $('rating-slider').classList.contains('unset');
  r.hidden = false;
}
function sendTrust() {
  // A timer fires late on a busy page; a move that finds the period over sends at once, and the
  // late timer must not then send the same position again.
  clearTimeout(drive.trustTimer);
  drive.trustTimer = null;
  drive.trustSentMs = performance.now();
  drive.scale = Number($('rating-slider').value);
  send({type: 'trust', value: drive.scale});
}
function scaleMoved() {
  if (!continuous() || !SCALE_PHASES.includes(drive.phase)) return;
  $('start').disabled = false;
  const wait = (drive.trustSentMs || -Infinity) + TRUST_SEND_MS - performance.now();
  if (wait <= 0) sendTrust();
  // setTimeout takes whole milliseconds and would cut the fraction, sending a little early
  else if (!drive.trustTimer) drive.trustTimer = setTimeout(sendTrust, Math.ceil(wait));
}
// The scale shows no thumb until it is touched (a visual-analogue scale: no default answer to
// lean on), and any touch of it is an answer, wherever it lands: a click on the very spot where
// the hidden thumb stands changes no value and so fires no 'input' event, hence 'click' too.
function rated() {
  $('rating-slider').classList.remove('unset');
  $('rating-value').textContent = $('rating-slider').value;
  $('rating-submit').disabled = false;
}
$('rating-slider').addEventListener('input', () => { rated(); scaleMoved(); });
$('rating-slider').addEventListener('click', () => { rated(); scaleMoved(); });
$('rating-submit').addEventListener('click', () => {
  if (drive.prompt === null || $('rating-slider').classList.contains('unset')) return;
  send({type: 'rating', id: drive.prompt, value: Number($('rating-slider').value)});
  hideRating();
});

// ---- questionnaire -------------------------------------------------------------------------
function showQuestionnaire(items) {
  const body = $('items');
  body.innerHTML = '';
  items.forEach((text, i) => {
    const row = document.createElement('tr');
    const cell = document.createElement('td');
    cell.textContent = `${i + 1}. ${text}`;
    row.appendChild(cell);
    for (let v = 1; v <= 7; v++) {
      const td = document.createElement('td');
      td.innerHTML = `<input type="radio" name="item${i + 1}" value="${v}" required aria-label="${v}">`;
      row.appendChild(td);
    }
    body.appendChild(row);
  });
  $('questionnaire-missing').textContent = '';
  $('questionnaire').hidden = false;
}
$('questionnaire').addEventListener('submit', (e) => {
  e.preventDefault();
  const answers = [];
  for (let i = 1; i <= 12; i++) {
    const checked = document.querySelector(`input[name="item${i}"]:checked`);
    if (!checked) { $('questionnaire-missing').textContent = `Please answer statement ${i}.`; return; }
    answers.push(Number(checked.value));
  }
  send({type: 'questionnaire', answers});
  $('questionnaire').hidden = true;
  setStatus('questionnaire sent');
});

// ---- drawing -------------------------------------------------------------------------------
function interpolated(nowMs) {
  const f = drive.frames;
  if (!f.length) return null;
  const t = nowMs - RENDER_DELAY_MS;
  let a = f[0], b = f[f.length - 1];
  for (let i = f.length - 1; i > 0; i--) {
    if (f[i - 1].received_ms <= t) { a = f[i - 1]; b = f[i]; break; }
  }
  const span = b.received_ms - a.received_ms;
  const w = span > 0 ? Math.max(0, Math.min(1, (t - a.received_ms) / span)) : 1;
  const out = {avAccel: b.av_accel_mps2, leftS: b.left_s, frameMs: b.received_ms,
               key: `${a.received_ms} ${b.received_ms} ${w}`};   // what the view shows
  for (const name of ['lead', 'av', 'you']) {
    const va = a.vehicles[name], vb = b.vehicles[name];
    if (!va || !vb) { out[name] = vb || va || null; continue; }
    out[name] = [va[0] + w * (vb[0] - va[0]), va[1] + w * (vb[1] - va[1])];
  }
  return out;
}

// A number shown, and its data- value, written only when it changed (writing the same text
// again still lays out and paints the page).
function setShown(id, text, key, value) {
  const el = $(id);
  if (el.textContent !== text) el.textContent = text;
  if (key && el.dataset[key] !== value) el.dataset[key] = value;
}

function draw(nowMs) {
  if (drive.phase === 'driving' && drive.inputTimer !== null) {
    updatePedal(nowMs);
    const changed = drive.lastSentPedal === null || Math.abs(drive.pedal - drive.lastSentPedal) > 1e-3;
    if (drive.pressWaiting || (changed && nowMs - drive.lastSentMs >= periodMs())) sendSample(nowMs);
  }
  const s = interpolated(nowMs);
  drive.displayed = s;
  if (s && s.you) {
    // drawn again only when it changed (between drives the last frame stays as it is)
    const key = `${s.key} ${$('top-down').checked} ${$('road').clientWidth}`;
    if (key !== drive.drawnKey) view.draw(s, $('top-down').checked);
    drive.drawnKey = key;
    setShown('speed', `${(s.you[1] * 3.6).toFixed(1)} km/h`, 'mps', s.you[1].toFixed(3));
    if (s.av) {
      const gap = s.av[0] - VEHICLE_LENGTH_M - s.you[0];
      setShown('gap', `${gap.toFixed(1)} m`, 'm', gap.toFixed(3));
      setShown('av-speed', `${(s.av[1] * 3.6).toFixed(1)} km/h`, 'mps', s.av[1].toFixed(3));
    }
    if (drive.phase === 'driving' && typeof s.leftS === 'number') {
      const left = Math.max(0, s.leftS - (nowMs - s.frameMs) / 1000);
      setShown('time-left', `${left.toFixed(0)} s`, 's', left.toFixed(2));
    }
  } else {
    view.blank();
    drive.drawnKey = null;
  }
  setShown('pedal-value', drive.pedal.toFixed(2));
  const mark = `${(1 - drive.pedal) / 2 * 196}px`;
  if ($('pedal-mark').style.top !== mark) $('pedal-mark').style.top = mark;
  requestAnimationFrame(draw);
}

connect();
requestAnimationFrame(draw);
