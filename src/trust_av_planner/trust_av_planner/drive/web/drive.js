// trust-av drive: the participant's page. Plain JS, no build step.
// State frames arrive over the WebSocket (a few per control period); the road is drawn at the
// display's frame rate, interpolating the frames RENDER_DELAY_MS behind the newest one.
// Pedal samples are stamped (performance.now()) and sent at the control rate.
'use strict';

const RENDER_DELAY_MS = 100;
const VEHICLE_LENGTH_M = 4.5;
const KEY_GAS_PER_S = 1.5, KEY_BRAKE_PER_S = 2.5, KEY_RELEASE_PER_S = 4.0;

const drive = {
  phase: 'connecting', controlRateHz: 10, ratingPeriodS: 15, accelMax: 2.5, accelMin: -6.0,
  frames: [], displayed: null, pedal: 0, seq: 0, sent: new Map(), durationS: 0,
  drivingSinceMs: null, keys: new Set(), pointerPedal: null, nextRatingMs: null,
  ratingShownMs: null, ws: null, inputTimer: null, source: 'none',
};
window.drive = drive;

const $ = (id) => document.getElementById(id);

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  drive.ws = ws;
  ws.onopen = () => setStatus('connected');
  ws.onmessage = (event) => onMessage(JSON.parse(event.data));
  ws.onclose = () => {
    setStatus('connection lost: reconnecting…');
    stopInput();
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
    drive.ratingPeriodS = msg.rating_period_s;
    drive.accelMax = msg.accel_max_mps2;
    drive.accelMin = msg.accel_min_mps2;
    if (msg.phase) setPhase(msg);
  } else if (msg.type === 'phase') {
    setPhase(msg);
  } else if (msg.type === 'state') {
    msg.received_ms = performance.now();
    drive.frames.push(msg);
    if (drive.frames.length > 50) drive.frames.shift();
    if (msg.ack) {
      const sentMs = drive.sent.get(msg.ack.seq);
      if (sentMs !== undefined) {
        send({type: 'latency', seq: msg.ack.seq, round_trip_ms: msg.received_ms - sentMs,
              graph_ms: msg.ack.graph_ms, back_ms: msg.ack.back_ms});
        drive.sent.delete(msg.ack.seq);
      }
    }
  }
}

function setPhase(msg) {
  drive.phase = msg.phase;
  $('start').hidden = true;
  $('questionnaire').hidden = true;
  $('message').hidden = true;
  if (msg.phase === 'ready') {
    $('title').textContent = msg.condition === 'practice' ? 'Practice drive' : `Drive ${msg.drive}`;
    drive.durationS = msg.duration_s;
    $('start').textContent = msg.condition === 'practice' ? 'Start the practice drive' : 'Start the drive';
    $('start').hidden = false;
    setStatus('ready');
  } else if (msg.phase === 'driving') {
    drive.durationS = msg.duration_s;
    if (drive.drivingSinceMs === null) drive.drivingSinceMs = performance.now();
    drive.nextRatingMs = performance.now() + drive.ratingPeriodS * 1000;
    startInput();
    setStatus('driving');
  } else if (msg.phase === 'questionnaire') {
    stopInput();
    showQuestionnaire(msg.items);
    setStatus('questionnaire');
  } else {
    stopInput();
    $('message').hidden = false;
    $('message').textContent = {
      finished: 'Thank you: the session is complete.',
      wait: 'Drive complete. Please wait a moment.',
    }[msg.phase] || 'The session is paused. The experimenter will resume it.';
    setStatus(msg.phase);
  }
  if (msg.phase !== 'driving') { drive.drivingSinceMs = null; hideRating(); }
}

// ---- input -------------------------------------------------------------------------------
function gamepadPedal() {
  const pads = navigator.getGamepads ? Array.from(navigator.getGamepads()).filter(Boolean) : [];
  if (!pads.length) return null;
  const pad = pads[0];
  const gas = pad.buttons[7] ? pad.buttons[7].value : 0;
  const brake = pad.buttons[6] ? pad.buttons[6].value : 0;
  const axis = pad.axes.length > 1 ? -pad.axes[1] : 0;   // stick or wheel pedal axis
  const value = Math.abs(gas - brake) > 0.02 ? gas - brake : (Math.abs(axis) > 0.05 ? axis : 0);
  return value;
}

let lastKeyMs = performance.now();
function updatePedal(nowMs) {
  const dt = Math.min(0.1, (nowMs - lastKeyMs) / 1000);
  lastKeyMs = nowMs;
  if (drive.pointerPedal !== null) { drive.pedal = drive.pointerPedal; drive.source = 'pointer'; return; }
  const pad = gamepadPedal();
  if (pad !== null && pad !== 0) { drive.pedal = pad; drive.source = 'gamepad'; return; }
  const gas = drive.keys.has('ArrowUp') || drive.keys.has('KeyW');
  const brake = drive.keys.has('ArrowDown') || drive.keys.has('KeyS');
  let p = drive.pedal;
  if (gas && !brake) p = Math.min(1, Math.max(0, p) + KEY_GAS_PER_S * dt);
  else if (brake && !gas) p = Math.max(-1, Math.min(0, p) - KEY_BRAKE_PER_S * dt);
  else p = p > 0 ? Math.max(0, p - KEY_RELEASE_PER_S * dt) : Math.min(0, p + KEY_RELEASE_PER_S * dt);
  drive.pedal = p;
  drive.source = 'keyboard';
}

function pedalAccel(p) { return p >= 0 ? p * drive.accelMax : -p * drive.accelMin; }

window.addEventListener('keydown', (e) => {
  if (['ArrowUp', 'ArrowDown', 'KeyW', 'KeyS'].includes(e.code)) { drive.keys.add(e.code); e.preventDefault(); }
});
window.addEventListener('keyup', (e) => drive.keys.delete(e.code));
window.addEventListener('blur', () => drive.keys.clear());

const pedalEl = $('pedal');
function pointerValue(e) {
  const r = pedalEl.getBoundingClientRect();
  return Math.max(-1, Math.min(1, 1 - 2 * (e.clientY - r.top) / r.height));
}
pedalEl.addEventListener('pointerdown', (e) => {
  pedalEl.setPointerCapture(e.pointerId); drive.pointerPedal = pointerValue(e); e.preventDefault();
});
pedalEl.addEventListener('pointermove', (e) => { if (drive.pointerPedal !== null) drive.pointerPedal = pointerValue(e); });
const releasePointer = () => { drive.pointerPedal = null; drive.pedal = 0; };
pedalEl.addEventListener('pointerup', releasePointer);
pedalEl.addEventListener('pointercancel', releasePointer);

function startInput() {
  if (drive.inputTimer !== null) return;
  drive.inputTimer = setInterval(() => {
    updatePedal(performance.now());
    const seq = ++drive.seq;
    const pageMs = performance.now();
    drive.sent.set(seq, pageMs);
    if (drive.sent.size > 200) drive.sent.delete(drive.sent.keys().next().value);
    send({type: 'input', seq, accel_mps2: pedalAccel(drive.pedal), page_ms: pageMs});
  }, 1000 / drive.controlRateHz);
}

function stopInput() {
  if (drive.inputTimer !== null) clearInterval(drive.inputTimer);
  drive.inputTimer = null;
}

$('start').addEventListener('click', () => { $('start').hidden = true; send({type: 'ready'}); });

// ---- trust rating (non-blocking) -----------------------------------------------------------
function showRating(nowMs) {
  $('rating-slider').value = 50; $('rating-value').textContent = '50';
  $('rating').hidden = false;
  drive.ratingShownMs = nowMs;
}
function hideRating() { $('rating').hidden = true; drive.ratingShownMs = null; }
$('rating-slider').addEventListener('input', () => { $('rating-value').textContent = $('rating-slider').value; });
$('rating-submit').addEventListener('click', () => {
  if (drive.ratingShownMs === null) return;
  send({type: 'rating', value: Number($('rating-slider').value), shown_ms: drive.ratingShownMs,
        answered_ms: performance.now()});
  hideRating();
});

// ---- questionnaire -------------------------------------------------------------------------
function showQuestionnaire(items) {
  const list = $('items');
  list.innerHTML = '';
  items.forEach((text, i) => {
    const li = document.createElement('li');
    li.innerHTML = `<div>${text.replace(/</g, '&lt;')}</div><div class="answers"></div>`;
    for (let v = 1; v <= 7; v++) {
      const label = document.createElement('label');
      label.innerHTML = `<input type="radio" name="item${i + 1}" value="${v}" required> ${v}`;
      li.querySelector('.answers').appendChild(label);
    }
    list.appendChild(li);
  });
  $('questionnaire').hidden = false;
}
$('questionnaire').addEventListener('submit', (e) => {
  e.preventDefault();
  const answers = [];
  for (let i = 1; i <= 12; i++) {
    const checked = document.querySelector(`input[name="item${i}"]:checked`);
    if (!checked) return;
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
  const out = {};
  for (const name of ['lead', 'av', 'you']) {
    const va = a.vehicles[name], vb = b.vehicles[name];
    if (!va || !vb) { out[name] = vb || va || null; continue; }
    out[name] = [va[0] + w * (vb[0] - va[0]), va[1] + w * (vb[1] - va[1])];
  }
  return out;
}

function draw(nowMs) {
  if (drive.phase === 'driving') updatePedal(nowMs);
  const s = interpolated(nowMs);
  drive.displayed = s;
  const canvas = $('road'), ctx = canvas.getContext('2d');
  const W = canvas.width, H = canvas.height;
  ctx.fillStyle = '#3a3f47'; ctx.fillRect(0, 0, W, H);
  ctx.fillStyle = '#555b64'; ctx.fillRect(0, H / 2 - 50, W, 100);
  if (s && s.you) {
    const scale = 8;                               // px per m
    const origin = W * 0.2;                        // your front bumper
    const toX = (x) => origin + (x - s.you[0]) * scale;
    ctx.strokeStyle = '#ddd'; ctx.lineWidth = 3; ctx.setLineDash([30, 30]);
    ctx.lineDashOffset = (s.you[0] * scale) % 60;
    ctx.beginPath(); ctx.moveTo(0, H / 2 + 50); ctx.lineTo(W, H / 2 + 50); ctx.stroke();
    ctx.beginPath(); ctx.moveTo(0, H / 2 - 50); ctx.lineTo(W, H / 2 - 50); ctx.stroke();
    ctx.setLineDash([]);
    const cars = [['lead', '#9e9e9e', 'lead'], ['av', '#1e88e5', 'AV'], ['you', '#fb8c00', 'you']];
    for (const [name, colour, label] of cars) {
      const v = s[name];
      if (!v) continue;
      const x = toX(v[0]);
      ctx.fillStyle = colour;
      ctx.fillRect(x - VEHICLE_LENGTH_M * scale, H / 2 - 9, VEHICLE_LENGTH_M * scale, 18);
      ctx.fillStyle = '#fff'; ctx.font = '14px sans-serif';
      ctx.fillText(label, x - VEHICLE_LENGTH_M * scale, H / 2 - 16);
    }
    $('speed').textContent = `${(s.you[1] * 3.6).toFixed(1)} km/h`;
    $('speed').dataset.mps = s.you[1].toFixed(3);
    if (s.av) {
      const gap = s.av[0] - VEHICLE_LENGTH_M - s.you[0];
      $('gap').textContent = `${gap.toFixed(1)} m`;
      $('gap').dataset.m = gap.toFixed(3);
      $('av-speed').textContent = `${(s.av[1] * 3.6).toFixed(1)} km/h`;
      $('av-speed').dataset.mps = s.av[1].toFixed(3);
    }
  }
  $('pedal-value').textContent = drive.pedal.toFixed(2);
  $('pedal-mark').style.top = `${(1 - drive.pedal) / 2 * 196}px`;
  if (drive.phase === 'driving' && drive.drivingSinceMs !== null) {
    const left = Math.max(0, drive.durationS - (nowMs - drive.drivingSinceMs) / 1000);
    $('time-left').textContent = `${left.toFixed(0)} s`;
    if (drive.nextRatingMs !== null && nowMs >= drive.nextRatingMs) {
      if ($('rating').hidden) showRating(nowMs);   // one still open stays as it is
      drive.nextRatingMs = nowMs + drive.ratingPeriodS * 1000;
    }
  }
  requestAnimationFrame(draw);
}

connect();
requestAnimationFrame(draw);
