#version 300 es
// Step 1a (rigctl.render.kernels.splat): forward-splat one source's disparity into the view's half-resolution
// target. One point per half-resolution sample in the box of those that hold a disparity (the CPU kernel's
// spans, as a rectangle); the sample (i, j) is the
// source's pixel (2i, 2j) with disparity d, and lands at round((2i + d du) / 2), round((2j + d dv) / 2).
// The target is cleared to NONE and blended with MAX (EXT_float_blend): the largest disparity, the nearest
// surface, wins -- the depth test of the CPU renderer, exact and independent of draw order.
precision highp float;
precision highp int;

const float NONE = -1.0e6;          // "no disparity"
uniform highp sampler2D disparity;  // the source's full-resolution disparity (R32F)
uniform vec2 offset;                // (du, dv): source minus view, in horizontal spacings
uniform ivec2 lowSize;              // (wl, hl): the target's size
uniform ivec4 box;                  // the source's samples that hold a disparity: x0, y0, x1, y1 (half resolution)
out float vDisparity;

void main() {
    int width = box.z - box.x;      // drawArrays(POINTS, 0, width * height of the box)
    int i = box.x + gl_VertexID % width;
    int j = box.y + gl_VertexID / width;
    float d = texelFetch(disparity, ivec2(2 * i, 2 * j), 0).r;
    vDisparity = d;
    gl_PointSize = 1.0;
    if (d <= NONE) {
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);  // outside the clip volume: no fragment
        return;
    }
    vec2 t = roundEven((vec2(float(2 * i), float(2 * j)) + d * offset) * 0.5);  // numpy's rint
    gl_Position = vec4((t + 0.5) / vec2(lowSize) * 2.0 - 1.0, 0.0, 1.0);
}
