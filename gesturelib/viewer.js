// The explorer's pose viewer (gesturelib.widgets.PoseViewer): an anywidget module that draws
// the motions on a canvas, plays their sound and shows who is talking on a timeline.
function render({ model, el }) {
  const width = model.get("width"), height = 400, timelineHeight = 36;
  el.classList.add("gesturelib-viewer");
  const canvas = document.createElement("canvas");
  canvas.width = width; canvas.height = height;
  canvas.title = "drag to turn the view; double-click to face the agent again";
  const timeline = document.createElement("canvas");
  timeline.width = width; timeline.height = timelineHeight;
  timeline.title = "who is talking; click to jump there";
  const audio = document.createElement("audio");
  audio.controls = true; audio.style.width = width + "px";
  el.append(canvas, timeline, audio);
  const ctx = canvas.getContext("2d"), tctx = timeline.getContext("2d");
  let yaw = 0, dragging = null, motions = null, frames = 0, count = 0, limits = null;

  function load() {
    const view = model.get("motions");
    const buffer = view.buffer.slice(view.byteOffset, view.byteOffset + view.byteLength);
    motions = new Float32Array(buffer);
    count = model.get("count"); frames = count ? motions.length / (count * 9 * 3) : 0;
    let high = 1;  // the farthest any joint gets from the root, for one scale in every panel
    for (let i = 0; i < motions.length; i += 3)
      high = Math.max(high, Math.hypot(motions[i], motions[i + 1], motions[i + 2]));
    limits = high * 1.15;
    drawTimeline(); draw();
  }
  function joint(k, t, j) {
    if (j < 0) return [0, 0, 0];
    const o = ((k * frames + t) * 9 + j) * 3;
    return [motions[o], motions[o + 1], motions[o + 2]];
  }
  function project([x, y, z], panel) {
    // Yaw 0 is the front view: the agent faces you, so its left (+x) is on your right.
    const c = Math.cos(yaw), s = Math.sin(yaw);
    const h = c * x + s * z, depth = -s * x + c * z;
    const panelWidth = width / count, scale = (Math.min(panelWidth, height - 40) / 2) / limits;
    return [panelWidth * (panel + 0.5) + h * scale, height / 2 + 10 - (y - limits * 0.35) * scale, depth];
  }
  function frameNow() {
    return Math.min(frames - 1, Math.max(0, Math.floor(audio.currentTime * model.get("fps"))));
  }
  function draw() {
    ctx.clearRect(0, 0, width, height);
    if (!frames) return;
    const t = frameNow(), bones = model.get("bones"), colours = model.get("colours");
    const titles = model.get("titles");
    for (let k = 0; k < count; k++) {
      // Painter's order: the bones farthest from you first, so the near arm is drawn over them.
      const segments = bones.map(([a, b], i) => {
        const p = project(joint(k, t, a), k), q = project(joint(k, t, b), k);
        return { p, q, colour: colours[i], depth: (p[2] + q[2]) / 2 };
      }).sort((u, v) => u.depth - v.depth);
      for (const { p, q, colour } of segments) {
        ctx.strokeStyle = colour; ctx.lineWidth = 4; ctx.lineCap = "round";
        ctx.beginPath(); ctx.moveTo(p[0], p[1]); ctx.lineTo(q[0], q[1]); ctx.stroke();
      }
      ctx.fillStyle = "#222"; ctx.font = "14px sans-serif"; ctx.textAlign = "center";
      ctx.fillText(titles[k], (width / count) * (k + 0.5), 20);
    }
    ctx.textAlign = "left"; ctx.font = "13px sans-serif"; ctx.fillStyle = "#222";
    ctx.fillText(`${(t / model.get("fps")).toFixed(1)} s`, 8, height - 10);
    const legend = model.get("legend");
    let x = width - 8;
    ctx.textAlign = "right";
    for (const [label, colour] of legend.slice().reverse()) {
      ctx.fillStyle = colour; ctx.fillText(label, x, height - 10);
      x -= ctx.measureText(label).width + 16;
    }
    drawPlayhead(t);
  }
  function drawTimeline() {
    const activity = model.get("activity"), palette = model.get("palette");
    tctx.clearRect(0, 0, width, timelineHeight);
    activity.forEach((code, t) => {
      tctx.fillStyle = palette[code];
      tctx.fillRect((t / activity.length) * width, 0, width / activity.length + 1, timelineHeight - 14);
    });
    tctx.font = "11px sans-serif"; tctx.textAlign = "left";
    let x = 4;
    tctx.fillStyle = "#222"; tctx.fillText("who is talking:", x, timelineHeight - 2);
    x += tctx.measureText("who is talking:").width + 8;
    for (const [label, colour] of model.get("talking_legend")) {
      tctx.fillStyle = colour; tctx.fillRect(x, timelineHeight - 11, 10, 10);
      tctx.fillStyle = "#222"; tctx.fillText(label, x + 13, timelineHeight - 2);
      x += 13 + tctx.measureText(label).width + 12;
    }
  }
  function drawPlayhead(t) {
    drawTimeline();
    const x = (t / Math.max(frames, 1)) * width;
    tctx.fillStyle = "#000"; tctx.fillRect(x - 1, 0, 2, timelineHeight - 14);
  }
  function loop() { draw(); if (!audio.paused) requestAnimationFrame(loop); }
  audio.addEventListener("play", () => requestAnimationFrame(loop));
  audio.addEventListener("seeked", draw);
  timeline.addEventListener("click", (e) => {
    audio.currentTime = (e.offsetX / width) * frames / model.get("fps"); draw();
  });
  canvas.addEventListener("pointerdown", (e) => { dragging = [e.clientX, yaw]; });
  window.addEventListener("pointerup", () => { dragging = null; });
  canvas.addEventListener("pointermove", (e) => {
    if (dragging) { yaw = dragging[1] + (e.clientX - dragging[0]) / 100; draw(); }
  });
  canvas.addEventListener("dblclick", () => { yaw = 0; draw(); });
  model.on("change:motions", load);
  // The sound is set only when it changes: setting it reloads the player and rewinds it.
  model.on("change:audio", () => { audio.src = model.get("audio"); });
  audio.src = model.get("audio");
  load();
}
export default { render };
