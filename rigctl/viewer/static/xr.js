// WebXR: when the browser offers an immersive VR session, each eye's pose (metres, from the session's local
// reference space) moves that eye within the array's window -- x to the right and y up map to columns and
// rows through the rig's horizontal spacing, around the eye's position when the session began -- and the two
// views are drawn into the session's layer side by side as the layer asks.

export async function offerXr(viewer, button) {
  if (!navigator.xr || !(await navigator.xr.isSessionSupported("immersive-vr").catch(() => false))) return;
  button.hidden = false;
  button.onclick = async () => {
    const gl = viewer.gl;
    const session = await navigator.xr.requestSession("immersive-vr");
    await gl.makeXRCompatible();
    const layer = new XRWebGLLayer(session, gl);
    session.updateRenderState({ baseLayer: layer });
    const space = await session.requestReferenceSpace("local");
    const origin = [viewer.col, viewer.row];
    const s = viewer.take.spacing_m;
    const frame = (t, xrFrame) => {
      session.requestAnimationFrame(frame);
      const pose = xrFrame.getViewerPose(space);
      viewer.tick(t);
      if (!pose) return;
      pose.views.forEach((view, i) => {
        const p = view.transform.position;
        const { col: c, row: r } = viewer.take.limits;
        const col = Math.min(Math.max(origin[0] + p.x / s, c[0]), c[1]);
        const row = Math.min(Math.max(origin[1] - p.y / s, r[0]), r[1]);
        viewer.r.render(...viewer.r.position(col, row), viewer.views[i]);
        const vp = layer.getViewport(view);
        viewer.r.present([viewer.views[i]], layer.framebuffer, vp);
      });
    };
    session.requestAnimationFrame(frame);
  };
}
