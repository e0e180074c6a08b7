// Probes for tests and the benchmark, run only when the server was started to accept results (never by
// `rigctl view` itself). Each posts what it measured to /api/result?tag=...:
//   probe=shots&frame=I&at=C,R;C,R&loo=CAM,CAM  the views' RGBA8 pixels as rendered (tags at:C,R / loo:CAM;
//     &stereo=C,R&ipd=MM                          eye:L and eye:R, the page's stereo pair there;
//     &keys=K,K                                   keys pressed at 1,1: the eye's place and keys:view)
//   probe=play                                  plays the take once; per frame shown, which frame set each
//                                               source's colour and disparity textures came from (tag play)
//   probe=bench&repeats=N&ipd=MM                eye pairs at the centre, timed (tag bench)
// then tag done (the GL implementation).

function post(tag, body) {
  return fetch(`/api/result?tag=${encodeURIComponent(tag)}`, { method: "POST", body });
}

const nextFrame = () => new Promise((resolve) => requestAnimationFrame(resolve));

async function shots(params, v) {
  const index = Number(params.get("frame") || 0);
  await v.store.load(index);
  v.show(index);
  const view = v.views[0];
  for (const at of (params.get("at") || "").split(";").filter(Boolean)) {
    const [c, r] = at.split(",").map(Number);
    const sources = v.r.render(...v.r.position(c, r), view);
    await post(`at:${at}`, v.r.read(view));
    await post(`sources:${at}`, JSON.stringify(sources));
  }
  if (params.has("stereo")) {  // the page's own eye pair: IPD in mm around C,R, as the stereo checkbox gives it
    const [c, r] = params.get("stereo").split(",").map(Number);
    document.getElementById("stereo").checked = true;
    document.getElementById("ipd").value = params.get("ipd") || "64";
    v.layout();
    v.move(c, r);
    for (const [i, [ec, er]] of v.eyes().entries()) {
      v.r.render(...v.r.position(ec, er), view);
      await post(`eye:${i ? "R" : "L"}`, v.r.read(view));
    }
  }
  if (params.has("keys")) {  // key presses from the centre camera, through the page's own handlers and draw
    document.getElementById("stereo").checked = false;
    v.layout();
    v.move(1, 1);
    for (const key of params.get("keys").split(",")) document.dispatchEvent(new KeyboardEvent("keydown", { key }));
    v.tick(performance.now());
    await post("keys", JSON.stringify({ col: v.col, row: v.row }));
    await post("keys:view", v.r.read(v.views[0]));
    for (let i = 0; i < 40; i++) document.dispatchEvent(new KeyboardEvent("keydown", { key: "ArrowRight" }));
    await post("limit", JSON.stringify({ col: v.col, row: v.row, shown: document.getElementById("position").textContent }));
  }
  for (const cam of (params.get("loo") || "").split(",").filter(Boolean)) {
    const offset = v.take.cameras.find((c) => c.name === cam).offset;
    const sources = v.r.render(offset[0], offset[1], view, [cam]);
    await post(`loo:${cam}`, v.r.read(view));
    await post(`sources:${cam}`, JSON.stringify(sources));
  }
}

async function play(v) {
  document.getElementById("loop").checked = false;
  const shown = [];
  const draw = v.draw.bind(v);
  v.draw = () => {
    draw();
    const srcs = v.r.sources;
    shown.push({ index: v.index, number: v.r.frame, t: performance.now(),
      colour: srcs.map((s) => s.tex.colourFrame), disparity: srcs.map((s) => s.tex.disparityFrame) });
  };
  await v.store.load(0);
  v.play();
  do { v.tick(await nextFrame()); } while (v.playing);
  await post("play", JSON.stringify({ shown, stalls: v.stalls }));
}

async function bench(params, v) {
  document.getElementById("stereo").checked = true;
  document.getElementById("ipd").value = params.get("ipd") || "64";
  await v.store.load(0);
  v.show(0);
  v.layout();
  const repeats = Number(params.get("repeats") || 20);
  v.times = [];
  for (let i = 0; i < repeats + 3; i++) { v.draw(); await nextFrame(); }
  const pairMs = v.times.slice(3);
  v.r.profile = {};  // then where the time goes, pass by pass (each waits for the GPU: a little slower)
  for (let i = 0; i < 3; i++) v.draw();
  for (const k of Object.keys(v.r.profile)) v.r.profile[k] /= 3;
  await post("bench", JSON.stringify({ pair_ms: pairMs, width: v.take.width, height: v.take.height, passes: v.r.profile }));
}

export async function runProbe(params, viewer, glName) {
  viewer.bindUi();
  const kind = params.get("probe");
  if (kind === "shots") await shots(params, viewer);
  else if (kind === "play") await play(viewer);
  else if (kind === "bench") await bench(params, viewer);
  else throw new Error(`unknown probe ${kind}`);
  await post("done", JSON.stringify({ gl: glName, userAgent: navigator.userAgent }));
}
