#version 300 es
// Steps 1b and 1e: grey-level morphology on the half-resolution disparity, as OpenCV's dilate / erode with a
// square kernel and the image's border ignored. radius 1 (3x3) for the closing of one-pixel cracks, 2 (5x5)
// for the ring of the key's soft edge. At most 25 fetches: a fixed amount of work per pixel. RADIUS and ERODE
// are constants the page sets when it compiles the shader (renderer.js: one program per use), so the loops
// unroll.
precision highp float;
precision highp int;

uniform highp sampler2D source;
const int radius = RADIUS;   // 1 or 2
const bool erode = ERODE;    // false: maximum (dilate), true: minimum (erode)
out float outDisparity;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    ivec2 size = textureSize(source, 0);
    float acc = erode ? 3.0e38 : -3.0e38;
    for (int dy = -radius; dy <= radius; dy++) {
        for (int dx = -radius; dx <= radius; dx++) {
            ivec2 q = p + ivec2(dx, dy);
            bool inside = all(greaterThanEqual(q, ivec2(0))) && all(lessThan(q, size));
            float v = texelFetch(source, clamp(q, ivec2(0), size - 1), 0).r;
            acc = inside ? (erode ? min(acc, v) : max(acc, v)) : acc;
        }
    }
    outDisparity = acc;
}
