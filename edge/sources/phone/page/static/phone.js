// reckon's phone page: DeviceMotion / DeviceOrientation samples and QR stand scans to the edge over
// a WebSocket (message formats: docs/phone.md). Samples are kept while the socket is down and sent
// when it is back, up to MAX_HELD (then the oldest go, counted on the page), so a short Wi-Fi drop
// loses nothing. Stand codes are read by the browser's BarcodeDetector where it reads QR codes;
// elsewhere the page sends small camera frames and the edge reads them. `?scan=frames` forces
// frames (tests, or a phone whose detector misreads).
"use strict";

const SEND_EVERY_MS = 100;        // one JSON batch per 100 ms: ~6-10 samples at a phone's 60-100 Hz
const MAX_HELD = 60 * 100;        // 60 s at 100 Hz while disconnected
const SCAN_EVERY_MS = 250;        // 4 looks a second: a stand held in view for 1 s is seen several times
const FRAME_LONG_SIDE_PX = 640;   // frames are scaled down to this; a stand code filling a third of
                                  // the view still has ~5 px per module
const FRAME_JPEG_QUALITY = 0.8;   // ~20-40 KB a frame, and module edges stay sharp enough to read
const JPEG_DATA_URL = "data:image/jpeg;base64,";
const SAME_CODE_AGAIN_MS = 5000;  // the same code seen again within this is not sent again
const RECONNECT_MS = 1000;

const state = { socket: null, motion: [], orientation: [], sent: 0, heldDropped: 0, noData: 0,
                lastText: "", lastTextAt: -Infinity, started: false, frames: 0, frameInFlight: false,
                detector: null, detecting: false };
const $ = (id) => document.getElementById(id);

// The phone's own clock in epoch ms with sub-ms resolution: event.timeStamp counts from timeOrigin.
const eventTime = (event) => performance.timeOrigin + event.timeStamp;
const nowTime = () => performance.timeOrigin + performance.now();

function show(id, text, cls) {
  const el = $(id);
  el.textContent = text;
  el.className = cls || "";
}

function connect() {
  const socket = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  socket.onopen = () => {
    state.socket = socket;
    document.body.dataset.state = "connected";
    show("connection", "connected", "ok");
    socket.send(JSON.stringify({ type: "hello", userAgent: navigator.userAgent }));
  };
  socket.onmessage = (event) => {
    const reply = JSON.parse(event.data);
    if (typeof reply.samples === "number") show("taken", String(reply.samples));
    if (reply.problem || reply.type === "problem") show("problem", reply.problem || reply.text, "bad");
    // One reply per message, in order: a frame's (it has `frame`) lets the next frame go; a refused
    // message may have been the frame, so it does too.
    if (reply.frame || reply.type === "problem") state.frameInFlight = false;
    if (reply.type === "scan_result") {
      const text = reply.accepted ? `accepted: stand ${reply.stand_id}` : `refused: ${reply.reason}`;
      show("scan", text, reply.accepted ? "ok" : "bad");
      document.body.dataset.lastScan = reply.accepted ? "accepted" : "refused";
    }
  };
  socket.onclose = () => {
    state.socket = null;
    state.frameInFlight = false;
    document.body.dataset.state = "disconnected";
    show("connection", "not connected: retrying", "bad");
    setTimeout(connect, RECONNECT_MS);
  };
}

function hold(list, row) {
  list.push(row);
  if (list.length > MAX_HELD) { list.shift(); state.heldDropped += 1; }
}

function onMotion(event) {
  const a = event.accelerationIncludingGravity, r = event.rotationRate;
  // Desktop browsers fire events without sensors; nothing to send then.
  if (!a || !r || a.x === null || r.alpha === null) { state.noData += 1; return; }
  hold(state.motion, [eventTime(event), a.x, a.y, a.z, r.alpha, r.beta, r.gamma, event.interval]);
}

function onOrientation(event) {
  if (event.alpha === null && event.beta === null) return;
  hold(state.orientation, [eventTime(event), event.alpha, event.beta, event.gamma, event.absolute ? 1 : 0]);
}

function flush() {
  const socket = state.socket;
  if (!socket || socket.readyState !== WebSocket.OPEN) return;
  if (state.motion.length) {
    socket.send(JSON.stringify({ type: "motion", samples: state.motion }));
    state.sent += state.motion.length;
    state.motion = [];
    show("sent", String(state.sent) + (state.heldDropped ? ` (${state.heldDropped} lost offline)` : ""));
  }
  if (state.orientation.length) {
    socket.send(JSON.stringify({ type: "orientation", samples: state.orientation }));
    state.orientation = [];
  }
  if (state.noData && !state.sent) show("problem", "this browser gives no motion sensor data", "bad");
}

function sendScan(text) {
  const now = nowTime();
  if (text === state.lastText && now - state.lastTextAt < SAME_CODE_AGAIN_MS) return;
  state.lastText = text;
  state.lastTextAt = now;
  show("scan", `sent: ${text}`);
  if (state.socket) state.socket.send(JSON.stringify({ type: "scan", t: now, text: text }));
}

// A BarcodeDetector that reads QR codes, or null (then frames go to the edge).
async function qrDetector() {
  if (new URLSearchParams(location.search).get("scan") === "frames" || !("BarcodeDetector" in window)) return null;
  try {
    const formats = await BarcodeDetector.getSupportedFormats();
    return formats.includes("qr_code") ? new BarcodeDetector({ formats: ["qr_code"] }) : null;
  } catch (error) {
    return null;
  }
}

async function detectCode(video) {
  if (state.detecting || !video.videoWidth) return;
  state.detecting = true;  // a slow detect() must not pile up calls
  try {
    const code = (await state.detector.detect(video)).find((found) => found.rawValue);
    if (code) sendScan(code.rawValue);
  } catch (error) {
    // A detector that claims QR codes but fails on this camera: the edge reads frames instead.
    show("problem", `barcode detector: ${error.message}; sending frames instead`, "bad");
    useFrames();
  } finally {
    state.detecting = false;
  }
}

// Frames go only while scanning: the camera shows something, the edge is connected, the page is in
// view, and the edge has answered the previous frame (one at a time: a slow link or a busy edge
// gets fewer frames, never a queue of stale ones). A frame is not kept while disconnected.
function sendFrame(video, canvas, context) {
  const socket = state.socket;
  if (!video.videoWidth || !socket || socket.readyState !== WebSocket.OPEN || document.hidden
      || state.frameInFlight) return;
  const scale = Math.min(1, FRAME_LONG_SIDE_PX / Math.max(video.videoWidth, video.videoHeight));
  canvas.width = Math.round(video.videoWidth * scale);
  canvas.height = Math.round(video.videoHeight * scale);
  const t = nowTime();
  context.drawImage(video, 0, 0, canvas.width, canvas.height);
  const url = canvas.toDataURL("image/jpeg", FRAME_JPEG_QUALITY);
  // A browser without a JPEG encoder gives PNG instead: too large to send several times a second.
  if (!url.startsWith(JPEG_DATA_URL)) { show("problem", "this browser cannot make JPEG frames", "bad"); return; }
  state.frameInFlight = true;
  state.frames += 1;
  socket.send(JSON.stringify({ type: "frame", t: t, width: canvas.width, height: canvas.height,
                               jpeg: url.slice(JPEG_DATA_URL.length) }));
  show("scanning", `frames sent to the edge: ${state.frames}`);
}

async function startCamera() {
  if (!navigator.mediaDevices || !navigator.mediaDevices.getUserMedia) {
    show("scan", "no camera here (needs HTTPS)", "bad");
    return;
  }
  const video = $("camera"), canvas = $("frame");
  const stream = await navigator.mediaDevices.getUserMedia({ video: { facingMode: "environment" }, audio: false });
  video.srcObject = stream;
  await video.play();
  const context = canvas.getContext("2d");
  state.detector = await qrDetector();
  if (state.detector) {
    document.body.dataset.scanPath = "detector";
    show("scanning", "read on this phone");
  } else {
    useFrames();
  }
  setInterval(() => (state.detector ? detectCode(video) : sendFrame(video, canvas, context)), SCAN_EVERY_MS);
}

function useFrames() {
  state.detector = null;
  document.body.dataset.scanPath = "frames";
  show("scanning", "frames sent to the edge: 0");
}

async function start() {
  if (state.started) return;
  // iOS asks for motion permission only from a user gesture (this click); others have no such call.
  for (const type of [window.DeviceMotionEvent, window.DeviceOrientationEvent]) {
    if (type && typeof type.requestPermission === "function") {
      const answer = await type.requestPermission();
      if (answer !== "granted") { show("problem", "motion permission refused: allow it in Settings", "bad"); return; }
    }
  }
  state.started = true;
  $("start").disabled = true;
  window.addEventListener("devicemotion", onMotion);
  window.addEventListener("deviceorientation", onOrientation);
  setInterval(flush, SEND_EVERY_MS);
  document.body.dataset.started = "yes";
  try { await startCamera(); } catch (error) { show("scan", `camera: ${error.message}`, "bad"); }
}

$("start").addEventListener("click", start);
connect();
