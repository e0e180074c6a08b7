#version 300 es
// Step 1d, search: for every pixel, the nearest pixel with a disparity before it and after it along a row
// (axis (1, 0)) or a column (axis (0, 1)), by pointer jumping: the first pass (stride 0) marks each pixel,
// each later pass with stride 1, 2, 4, ... looks one stride back and ahead, so after ceil(log2(size)) passes
// every pixel knows both ends of the run of holes it is in. Two fetches per pass, however far the disparities
// reach: the work per pixel does not depend on the disparity range.
precision highp float;
precision highp int;

const float NONE = -1.0e6;
const float FAR = 1.0e9;            // "no pixel after this one"
uniform highp sampler2D source;     // stride 0: the disparity; otherwise the previous pass (RG32F)
uniform int stride;
uniform ivec2 axis;
out vec2 outEnds;                   // (index before, index after) along the axis; -1 / FAR when none

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    if (stride == 0) {
        float here = float(axis.x == 1 ? p.x : p.y);
        outEnds = texelFetch(source, p, 0).r > NONE ? vec2(here) : vec2(-1.0, FAR);
        return;
    }
    ivec2 size = textureSize(source, 0);
    vec2 ends = texelFetch(source, p, 0).rg;
    ivec2 back = p - axis * stride;
    ivec2 ahead = p + axis * stride;
    if (ends.x < 0.0 && all(greaterThanEqual(back, ivec2(0)))) ends.x = texelFetch(source, back, 0).r;
    if (ends.y >= FAR && all(lessThan(ahead, size))) ends.y = texelFetch(source, ahead, 0).g;
    outEnds = ends;
}
