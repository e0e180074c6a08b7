// The light-field renderer on WebGL2: the same passes as rigctl.render (see shaders/*.glsl, one file per
// pass). A frame set's nine cameras are textures (RGBA8UI colour + key alpha, R32F disparity), uploaded
// together from one bundle; a view is the splat, closing, fill and ring at half resolution, then the shade
// at full resolution into an RGBA8UI target.

const NONE = -1e6;
const TAPS = 4;
const WEIGHT = 1 << 20;
const f32 = Math.fround;
const SHADERS = ["fullscreen.vert", "splat.vert", "splat.frag", "morph.frag", "cracks.frag", "scan.frag",
  "fill.frag", "shade.frag", "present.frag"];

export async function loadShaders(base) {
  const out = {};
  await Promise.all(SHADERS.map(async (name) => {
    const res = await fetch(`${base}/${name}.glsl`);
    if (!res.ok) throw new Error(`shader ${name}: HTTP ${res.status}`);
    out[name] = await res.text();
  }));
  return out;
}

function compile(gl, type, source, name) {
  const s = gl.createShader(type);
  gl.shaderSource(s, source);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(`${name}: ${gl.getShaderInfoLog(s)}`);
  return s;
}

// `defines` replace names in the fragment shader's text by constants (morph.frag's RADIUS and ERODE).
function program(gl, src, vert, frag, defines = {}) {
  const p = gl.createProgram();
  let text = src[frag];
  for (const [name, value] of Object.entries(defines)) text = text.replaceAll(name, value);
  gl.attachShader(p, compile(gl, gl.VERTEX_SHADER, src[vert], vert));
  gl.attachShader(p, compile(gl, gl.FRAGMENT_SHADER, text, frag));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(`${vert} + ${frag}: ${gl.getProgramInfoLog(p)}`);
  const uniforms = {};
  const count = gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS);
  for (let i = 0; i < count; i++) {
    const name = gl.getActiveUniform(p, i).name.replace(/\[0\]$/, "");
    uniforms[name] = gl.getUniformLocation(p, name);
  }
  return { p, u: uniforms };
}

function texture(gl, internal, format, type, w, h) {
  const t = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, t);
  gl.texStorage2D(gl.TEXTURE_2D, 1, internal, w, h);
  for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, gl.NEAREST], [gl.TEXTURE_MAG_FILTER, gl.NEAREST],
    [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE]]) gl.texParameteri(gl.TEXTURE_2D, k, v);
  return { t, w, h, format, type };
}

function target(gl, tex) {
  const fb = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
  gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex.t, 0);
  const status = gl.checkFramebufferStatus(gl.FRAMEBUFFER);
  if (status !== gl.FRAMEBUFFER_COMPLETE) throw new Error(`framebuffer incomplete (0x${status.toString(16)})`);
  return { ...tex, fb };
}

export function decodeBundle(buffer) {
  const bytes = new Uint8Array(buffer);
  const magic = String.fromCharCode(...bytes.subarray(0, 4));
  if (magic !== "RGFS") throw new Error("not a frame-set bundle");
  const len = new DataView(buffer).getUint32(4, true);
  const header = JSON.parse(new TextDecoder().decode(bytes.subarray(8, 8 + len)));
  const px = header.width * header.height;
  let at = 8 + len;
  const cameras = header.cameras.map((name) => {
    const colour = new Uint8Array(buffer, at, px * 4);
    const disparity = new Float32Array(buffer, at + px * 4, px);
    at += px * 8;
    return { name, colour, disparity };
  });
  return { header, cameras };
}

export class Renderer {
  constructor(gl, shaders, take) {
    this.gl = gl;
    for (const ext of ["EXT_color_buffer_float", "EXT_float_blend"]) {
      if (!gl.getExtension(ext)) throw new Error(`this browser's WebGL2 lacks ${ext}`);
    }
    this.take = take;
    const { width: w, height: h } = take;
    this.w = w; this.h = h;
    this.wl = (w + 1) >> 1; this.hl = (h + 1) >> 1;
    const src = shaders;
    this.progs = {
      splat: program(gl, src, "splat.vert", "splat.frag"),
      dilate3: program(gl, src, "fullscreen.vert", "morph.frag", { RADIUS: "1", ERODE: "false" }),
      erode3: program(gl, src, "fullscreen.vert", "morph.frag", { RADIUS: "1", ERODE: "true" }),
      dilate5: program(gl, src, "fullscreen.vert", "morph.frag", { RADIUS: "2", ERODE: "false" }),
      cracks: program(gl, src, "fullscreen.vert", "cracks.frag"),
      scan: program(gl, src, "fullscreen.vert", "scan.frag"),
      fill: program(gl, src, "fullscreen.vert", "fill.frag"),
      shade: program(gl, src, "fullscreen.vert", "shade.frag"),
      present: program(gl, src, "fullscreen.vert", "present.frag"),
    };
    this.vao = gl.createVertexArray();
    const lowTarget = () => target(gl, texture(gl, gl.R32F, gl.RED, gl.FLOAT, this.wl, this.hl));
    const endsTarget = () => target(gl, texture(gl, gl.RG32F, gl.RG, gl.FLOAT, this.wl, this.hl));
    this.low = [lowTarget(), lowTarget(), lowTarget(), lowTarget()];
    this.ends = [endsTarget(), endsTarget()];
    this.cameras = new Map();  // name -> {colour, disparity} textures and the frame set each came from
    this.frame = null;         // the frame set on the GPU
    this.sources = [];         // cameras with a disparity in that frame set, with their offsets
    this.maxGap = 4;
  }

  newView() {
    const gl = this.gl;
    return target(gl, texture(gl, gl.RGBA8UI, gl.RGBA_INTEGER, gl.UNSIGNED_BYTE, this.w, this.h));
  }

  // Every camera of one frame set, colour and disparity from the same bundle: never a mix of two frame sets.
  upload(bundle) {
    const gl = this.gl;
    const { header, cameras } = bundle;
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    for (const cam of cameras) {
      let t = this.cameras.get(cam.name);
      if (!t) {
        t = {
          colour: texture(gl, gl.RGBA8UI, gl.RGBA_INTEGER, gl.UNSIGNED_BYTE, this.w, this.h),
          disparity: texture(gl, gl.R32F, gl.RED, gl.FLOAT, this.w, this.h),
        };
        this.cameras.set(cam.name, t);
      }
      gl.bindTexture(gl.TEXTURE_2D, t.colour.t);
      gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, this.w, this.h, gl.RGBA_INTEGER, gl.UNSIGNED_BYTE, cam.colour);
      t.colourFrame = header.number;
      gl.bindTexture(gl.TEXTURE_2D, t.disparity.t);
      gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, this.w, this.h, gl.RED, gl.FLOAT, cam.disparity);
      t.disparityFrame = header.number;
    }
    const offsets = new Map(this.take.cameras.map((c) => [c.name, c.offset]));
    this.sources = cameras.map((c, k) => ({
      name: c.name, offset: offsets.get(c.name), tex: this.cameras.get(c.name), box: header.boxes[k],
    }));
    this.maxGap = header.max_gap;
    this.frame = header.number;
  }

  // Grid units (column, row) -> (u, v) in horizontal spacings: the fit rigctl render uses for --at.
  position(col, row) {
    const f = this.take.fit;
    return [f[0][0] + col * f[1][0] + row * f[2][0], f[0][1] + col * f[1][1] + row * f[2][1]];
  }

  nearest(u, v, exclude = []) {
    const pool = this.sources.filter((s) => !exclude.includes(s.name));
    const d2 = (s) => (s.offset[0] - u) ** 2 + (s.offset[1] - v) ** 2;
    pool.sort((a, b) => d2(a) - d2(b) || (a.name < b.name ? -1 : a.name > b.name ? 1 : 0));
    return pool.slice(0, TAPS);
  }

  pass(prog, out, uniforms, textures) {
    const gl = this.gl;
    gl.useProgram(prog.p);
    gl.bindFramebuffer(gl.FRAMEBUFFER, out.fb);
    gl.viewport(0, 0, out.w, out.h);
    let unit = 0;
    for (const [name, tex] of Object.entries(textures)) {
      gl.activeTexture(gl.TEXTURE0 + unit);
      gl.bindTexture(gl.TEXTURE_2D, tex.t);
      gl.uniform1i(prog.u[name], unit++);
    }
    for (const [name, [fn, ...v]] of Object.entries(uniforms)) gl[fn](prog.u[name], ...v);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
  }

  // With `this.profile` set (an object), each stage waits for the GPU and adds its milliseconds there.
  mark(stage, fb) {
    if (!this.profile) return;
    const gl = this.gl;
    gl.bindFramebuffer(gl.FRAMEBUFFER, fb.fb);
    const type = fb === this._view ? [gl.RGBA_INTEGER, gl.UNSIGNED_INT, new Uint32Array(4)] : [gl.RGBA, gl.FLOAT, new Float32Array(4)];
    gl.readPixels(0, 0, 1, 1, ...type);
    const now = performance.now();
    this.profile[stage] = (this.profile[stage] || 0) + now - this._t;
    this._t = now;
  }

  // The view at (u, v) into `view` (from newView()); returns the sources used.
  render(u, v, view, exclude = []) {
    const gl = this.gl;
    this._view = view;
    this._t = performance.now();
    const srcs = this.nearest(u, v, exclude);
    if (!srcs.length) throw new Error("no source cameras");
    const du = srcs.map((s) => { const x = f32(s.offset[0] - u); return Math.abs(x) < 1e-6 ? 0 : x; });
    const dv = srcs.map((s) => { const y = f32(s.offset[1] - v); return Math.abs(y) < 1e-6 ? 0 : y; });
    const close = du.map((x, k) => f32(1 / (Math.hypot(x, dv[k]) + 0.1) ** 2));
    const scale = f32(WEIGHT / Math.max(...close));
    const agree = f32(1 / 1.5);
    gl.bindVertexArray(this.vao);
    const [a, b, c, d] = this.low;
    // 1a: splat every source, MAX blend into a target cleared to NONE
    gl.bindFramebuffer(gl.FRAMEBUFFER, a.fb);
    gl.viewport(0, 0, this.wl, this.hl);
    gl.clearBufferfv(gl.COLOR, 0, [NONE, 0, 0, 0]);
    gl.enable(gl.BLEND);
    gl.blendEquation(gl.MAX);
    const sp = this.progs.splat;
    gl.useProgram(sp.p);
    gl.uniform2i(sp.u.lowSize, this.wl, this.hl);
    gl.activeTexture(gl.TEXTURE0);
    gl.uniform1i(sp.u.disparity, 0);
    srcs.forEach((s, k) => {
      const [x0, y0, x1, y1] = s.box;
      gl.bindTexture(gl.TEXTURE_2D, s.tex.disparity.t);
      gl.uniform2f(sp.u.offset, du[k], dv[k]);
      gl.uniform4i(sp.u.box, x0, y0, x1, y1);
      if (x1 > x0 && y1 > y0) gl.drawArrays(gl.POINTS, 0, (x1 - x0) * (y1 - y0));
    });
    gl.disable(gl.BLEND);
    this.mark("splat", a);
    // 1b, 1c: close one-pixel cracks
    this.pass(this.progs.dilate3, b, {}, { source: a });
    this.pass(this.progs.erode3, c, {}, { source: b });
    this.pass(this.progs.cracks, b, {}, { splatted: a, closed: c });
    this.mark("close", b);
    // 1d: fill disocclusions from the background side, rows then columns
    let cur = b, spare = a;
    for (const axis of [[1, 0], [0, 1]]) {
      const size = axis[0] ? this.wl : this.hl;
      let [e0, e1] = this.ends;
      this.pass(this.progs.scan, e0, { stride: ["uniform1i", 0], axis: ["uniform2i", ...axis] }, { source: cur });
      for (let stride = 1; stride < size; stride *= 2) {
        this.pass(this.progs.scan, e1, { stride: ["uniform1i", stride], axis: ["uniform2i", ...axis] }, { source: e0 });
        [e0, e1] = [e1, e0];
      }
      this.pass(this.progs.fill, spare, { axis: ["uniform2i", ...axis], maxGap: ["uniform1i", this.maxGap] },
        { source: cur, ends: e0 });
      [cur, spare] = [spare, cur];
    }
    this.mark("fill", cur);
    // 1e: the ring of the key's soft edge
    this.pass(this.progs.dilate5, d, {}, { source: cur });
    // 2-3: shade
    const textures = { target: cur, ring: d };
    for (let k = 0; k < TAPS; k++) {
      const s = srcs[Math.min(k, srcs.length - 1)];
      textures[`colour${k}`] = s.tex.colour;
      textures[`disparity${k}`] = s.tex.disparity;
    }
    const off = new Float32Array(2 * TAPS), w = new Float32Array(3 * TAPS);
    srcs.forEach((s, k) => {
      const cl = f32(close[k] * scale);
      off.set([du[k], dv[k]], 2 * k);
      w.set([cl, f32(cl * agree), f32(cl * f32(1e-3))], 3 * k);
    });
    this.pass(this.progs.shade, view, {
      n: ["uniform1i", srcs.length], offset: ["uniform2fv", off], weight: ["uniform3fv", w], size: ["uniform2i", this.w, this.h],
    }, textures);
    this.mark("shade", view);
    return srcs.map((s) => s.name);
  }

  // A view's pixels as they were rendered: RGBA8, straight alpha, first image row first.
  read(view) {
    const gl = this.gl;
    gl.bindFramebuffer(gl.FRAMEBUFFER, view.fb);
    const out = new Uint32Array(view.w * view.h * 4);
    gl.readPixels(0, 0, view.w, view.h, gl.RGBA_INTEGER, gl.UNSIGNED_INT, out);
    return Uint8Array.from(out);
  }

  // Views side by side on the canvas (one, or an eye pair), over a checkerboard.
  // (or into `framebuffer` at `area`: a WebXR layer's eye).
  present(views, framebuffer = null, area = null) {
    const gl = this.gl;
    const canvas = gl.canvas;
    gl.bindFramebuffer(gl.FRAMEBUFFER, framebuffer);
    const pr = this.progs.present;
    gl.useProgram(pr.p);
    const each = Math.floor(canvas.width / views.length);
    views.forEach((view, i) => {
      const [x, y, w, h] = area ? [area.x, area.y, area.width, area.height] : [i * each, 0, each, canvas.height];
      gl.viewport(x, y, w, h);
      gl.activeTexture(gl.TEXTURE0);
      gl.bindTexture(gl.TEXTURE_2D, view.t);
      gl.uniform1i(pr.u.view, 0);
      gl.uniform4i(pr.u.viewport, x, y, w, h);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
    });
  }
}
