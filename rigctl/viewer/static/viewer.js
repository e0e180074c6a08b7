// The page: the eye's position in the array's window, playback of the take's frame sets, stereo and WebXR,
// the frame time; probes for tests and the benchmark when the server accepts results (probe.js).

import { Renderer, loadShaders } from "./renderer.js";
import { FrameStore } from "./frames.js";
import { runProbe } from "./probe.js";

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);

function status(text, error = false) {
  $("status").textContent = text;
  $("status").className = error ? "error" : "";
}

function timecode(frames, fps) {
  const rate = Math.round(fps);
  const f = frames % rate, s = Math.floor(frames / rate);
  const two = (x) => String(x).padStart(2, "0");
  return `${two(Math.floor(s / 3600) % 24)}:${two(Math.floor(s / 60) % 60)}:${two(s % 60)}:${two(f)}`;
}

class Viewer {
  constructor(take, renderer, gl) {
    this.take = take; this.r = renderer; this.gl = gl;
    this.store = new FrameStore(take.frames);
    const centre = take.cameras.reduce((a, c) => [a[0] + c.col, a[1] + c.row], [0, 0]);
    this.home = [centre[0] / take.cameras.length, centre[1] / take.cameras.length];
    this.col = this.home[0]; this.row = this.home[1];
    this.index = 0; this.shown = -1;
    this.playing = false; this.clock = null;
    this.views = [renderer.newView(), renderer.newView()];
    this.times = [];
    this.stalls = 0;
    this.dirty = true;
    this.store.listeners.push((i, err) => {
      if (err) status(String(err), true);
      if (i === this.index) this.dirty = true;
    });
  }

  get stereo() { return $("stereo").checked; }
  get halfIpd() { return Number($("ipd").value) / 1000 / this.take.spacing_m / 2; }  // grid units (columns)

  // The eye kept inside the limits rigctl render enforces (both eyes, in stereo).
  move(col, row) {
    const { col: c, row: r } = this.take.limits;
    const half = this.stereo ? this.halfIpd : 0;
    this.col = Math.min(Math.max(col, c[0] + half), c[1] - half);
    this.row = Math.min(Math.max(row, r[0]), r[1]);
    this.dirty = true;
  }

  eyes() {
    if (!this.stereo) return [[this.col, this.row]];
    return [[this.col - this.halfIpd, this.row], [this.col + this.halfIpd, this.row]];
  }

  // Upload frame set `index` when it is here; false while it is still on its way.
  show(index) {
    const bundle = this.store.get(index);
    this.store.around(index, $("loop").checked);
    if (!bundle) { this.store.load(index).catch(() => {}); return false; }
    if (this.shown !== index) { this.r.upload(bundle); this.shown = index; }
    this.index = index;
    return true;
  }

  // Both eyes (or the one view), timed to the GPU's end of work (a one-pixel read-back waits for it).
  draw() {
    const gl = this.gl;
    const t0 = performance.now();
    const eyes = this.eyes();
    eyes.forEach(([c, r], i) => this.r.render(...this.r.position(c, r), this.views[i]));
    gl.bindFramebuffer(gl.FRAMEBUFFER, this.views[eyes.length - 1].fb);
    gl.readPixels(0, 0, 1, 1, gl.RGBA_INTEGER, gl.UNSIGNED_INT, new Uint32Array(4));
    this.times.push(performance.now() - t0);
    if (this.times.length > 30) this.times.shift();
    this.r.present(this.views.slice(0, eyes.length));
    this.hud();
  }

  hud() {
    const n = this.take.frames[this.index];
    $("frame").textContent = `frame ${n} (${this.index + 1}/${this.take.frames.length})`;
    $("timecode").textContent = this.take.timecodes[this.index] ?? timecode(n, this.take.fps);
    $("position").textContent = `eye ${this.col.toFixed(2)}, ${this.row.toFixed(2)} (columns ${this.take.limits.col
      .join("..")}, rows ${this.take.limits.row.join("..")})`;
    const sorted = [...this.times].sort((a, b) => a - b);
    $("timing").textContent = `${sorted[sorted.length >> 1].toFixed(1)} ms per ${this.stereo ? "eye pair" : "view"}` +
      (this.stalls ? `, ${this.stalls} waits for frames` : "");
    const eye = $("eye"), box = this.windowBox;
    eye.style.left = `${box.x(this.col)}px`; eye.style.top = `${box.y(this.row)}px`;
  }

  tick(now) {
    if (this.playing) {
      const period = 1000 / this.take.fps;
      if (this.clock === null) this.clock = { t: now, index: this.index };
      let due = this.clock.index + Math.floor((now - this.clock.t) / period);
      if (due >= this.take.frames.length) {
        if ($("loop").checked) { this.clock = { t: now, index: 0 }; due = 0; } else due = this.take.frames.length - 1;
      }
      if (due !== this.index) {
        if (this.show(due)) this.dirty = true;
        else {
          // not here yet: never skip ahead of what is loaded; wait for the next frame set and restart the clock
          // from it (a stall, counted), so a slow read shows every frame set late rather than none
          const next = Math.min(this.index + 1, this.take.frames.length - 1);
          if (next !== this.index && this.show(next)) this.dirty = true;
          this.clock = { t: now, index: this.index };
          this.stalls += 1;
        }
      }
      if (this.index === this.take.frames.length - 1 && !$("loop").checked) this.pause();  // the end, shown
    }
    if (this.dirty && this.show(this.index)) { this.dirty = false; this.draw(); }
  }

  play() { this.playing = true; this.clock = null; $("play").innerHTML = "&#10074;&#10074;"; }
  pause() { this.playing = false; $("play").innerHTML = "&#9654;"; }
  step(by) {
    const count = this.take.frames.length;
    this.pause();
    this.index = (this.index + by + count) % count;
    this.dirty = true;
  }

  bindUi() {
    const canvas = this.gl.canvas;
    let drag = null;
    const spanC = this.take.limits.col[1] - this.take.limits.col[0];
    const spanR = this.take.limits.row[1] - this.take.limits.row[0];
    canvas.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY, this.col, this.row]; canvas.setPointerCapture(e.pointerId); });
    canvas.addEventListener("pointerup", () => { drag = null; });
    canvas.addEventListener("pointermove", (e) => {
      if (!drag) return;
      const k = spanC / canvas.clientWidth;
      this.move(drag[2] - (e.clientX - drag[0]) * k, drag[3] - (e.clientY - drag[1]) * (spanR / canvas.clientHeight));
    });
    const win = $("window");
    const from = (e) => { const b = win.getBoundingClientRect(); this.move(this.windowBox.col(e.clientX - b.left), this.windowBox.row(e.clientY - b.top)); };
    win.addEventListener("pointerdown", (e) => { from(e); win.setPointerCapture(e.pointerId); win.onpointermove = from; });
    win.addEventListener("pointerup", () => { win.onpointermove = null; });
    document.addEventListener("keydown", (e) => {
      const s = e.shiftKey ? 0.02 : 0.1;
      const keys = {
        ArrowLeft: () => this.move(this.col - s, this.row), ArrowRight: () => this.move(this.col + s, this.row),
        ArrowUp: () => this.move(this.col, this.row - s), ArrowDown: () => this.move(this.col, this.row + s),
        " ": () => (this.playing ? this.pause() : this.play()), ",": () => this.step(-1), ".": () => this.step(1),
        s: () => { $("stereo").checked = !this.stereo; this.layout(); }, 0: () => this.move(...this.home),
      };
      if (keys[e.key] && e.target.tagName !== "INPUT") { keys[e.key](); e.preventDefault(); }
    });
    $("play").onclick = () => (this.playing ? this.pause() : this.play());
    $("prev").onclick = () => this.step(-1);
    $("next").onclick = () => this.step(1);
    $("stereo").onchange = () => this.layout();
    $("ipd").oninput = () => this.move(this.col, this.row);
    this.drawWindow();
    this.layout();
  }

  layout() {
    const canvas = this.gl.canvas;
    canvas.width = this.take.width * (this.stereo ? 2 : 1);
    canvas.height = this.take.height;
    this.move(this.col, this.row);
  }

  // The array's window (figure 5 of the paper): the cameras, and the box rigctl render allows.
  drawWindow() {
    const win = $("window"), { col: c, row: r } = this.take.limits;
    const w = win.clientWidth, h = win.clientHeight;
    this.windowBox = {
      x: (col) => ((col - c[0]) / (c[1] - c[0])) * w, y: (row) => ((row - r[0]) / (r[1] - r[0])) * h,
      col: (x) => c[0] + (x / w) * (c[1] - c[0]), row: (y) => r[0] + (y / h) * (r[1] - r[0]),
    };
    const grid = document.createElement("div");
    grid.className = "grid";
    Object.assign(grid.style, { left: `${this.windowBox.x(c[0] + 1)}px`, top: `${this.windowBox.y(r[0] + 1)}px`,
      width: `${this.windowBox.x(c[1] - 1) - this.windowBox.x(c[0] + 1)}px`,
      height: `${this.windowBox.y(r[1] - 1) - this.windowBox.y(r[0] + 1)}px` });
    win.appendChild(grid);
    for (const cam of this.take.cameras) {
      const dot = document.createElement("div");
      dot.className = "cam"; dot.title = cam.name;
      Object.assign(dot.style, { left: `${this.windowBox.x(cam.col)}px`, top: `${this.windowBox.y(cam.row)}px` });
      win.appendChild(dot);
    }
  }
}

async function main() {
  const take = await (await fetch("/api/take.json")).json();
  const canvas = $("view");
  const gl = canvas.getContext("webgl2", { antialias: false, premultipliedAlpha: false, preserveDrawingBuffer: true, xrCompatible: true });
  if (!gl) throw new Error("this browser offers no WebGL2");
  const info = gl.getExtension("WEBGL_debug_renderer_info");
  const glName = info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
  $("gl").textContent = glName;
  const renderer = new Renderer(gl, await loadShaders("/static/shaders"), take);
  const viewer = new Viewer(take, renderer, gl);
  window.rigctlViewer = viewer;
  if (take.results && params.has("probe")) {
    await runProbe(params, viewer, glName);
    return;
  }
  viewer.bindUi();
  if (params.has("ipd")) {  // a link can open the page in stereo (?ipd=64) and at a place (?at=1.5,1)
    $("stereo").checked = true;
    $("ipd").value = params.get("ipd");
    viewer.layout();
  }
  if (params.has("at")) viewer.move(...params.get("at").split(",").map(Number));
  const { offerXr } = await import("./xr.js");
  offerXr(viewer, $("xr"));
  await viewer.store.load(0);
  viewer.tick(performance.now());  // the first picture without waiting for an animation frame
  const loop = (now) => { viewer.tick(now); requestAnimationFrame(loop); };
  requestAnimationFrame(loop);
  status(`${take.width}x${take.height}, ${take.frames.length} frame sets at ${take.fps} fps`);
}

main().catch(async (err) => {
  status(String(err), true);
  await fetch("/api/result?tag=error", { method: "POST", body: String(err && err.stack || err) }).catch(() => {});
});
