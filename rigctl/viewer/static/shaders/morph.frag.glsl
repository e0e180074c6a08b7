#version 300 es
// Steps 1b and 1e: grey-level morphology on the half-resolution disparity, as OpenCV's dilate / erode with a
// square kernel and the image's border ignored. radius 1 (3x3) for the closing of one-pixel cracks, 2 (5x5)
// for the ring of the key's soft edge. At most 25 fetches: a fixed amount of work per pixel.
precision highp float;
precision highp int;

uniform highp sampler2D source;
uniform int radius;   // 1 or 2
uniform bool erode;   // false: maximum (dilate), true: minimum (erode)
out float outDisparity;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    ivec2 size = textureSize(source, 0);
    float acc = erode ? 3.0e38 : -3.0e38;
    for (int dy = -2; dy <= 2; dy++) {
        for (int dx = -2; dx <= 2; dx++) {
            ivec2 q = p + ivec2(dx, dy);
            bool inside = all(greaterThanEqual(q, ivec2(0))) && all(lessThan(q, size));
            if (abs(dx) > radius || abs(dy) > radius || !inside) continue;
            float v = texelFetch(source, q, 0).r;
            acc = erode ? min(acc, v) : max(acc, v);
        }
    }
    outDisparity = acc;
}
