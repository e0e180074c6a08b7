#version 300 es
// Steps 2 and 3 (rigctl.render.kernels.shade): the view's colour, one fragment per full-resolution pixel.
//
// The pixel's target disparity d is the half-resolution target's at its 2x2 block (or the ring's where the
// target has none: the key's soft edge); no disparity -> transparent black. For each of the n (at most 4)
// nearest sources, with (du, dv) the source's position minus the view's:
//   - where the point is in the source: the block's corner at (2bx - d du, 2by - d dv), plus the pixel's
//     place in its block -- so the pixels of a block share their bilinear weights, 7-bit (of 128);
//   - one bilinear RGBA sample there (four texel fetches, zero outside the image), in integers:
//     ((128 - q) a + q b + 64) >> 7 per channel, rows then columns, as the CPU kernel does;
//   - one nearest fetch of the source's own disparity there (NONE outside the image);
//   - its weight: closeness in the array plane x agreement of the two disparities, floored:
//     round(max(c - |seen - d| c / 1.5, c / 1000)), c scaled so the nearest source weighs 2^20;
// and the weighted sum over the weights, rounded to 8 bits. A fixed number of fetches per pixel (4 x 5),
// no loop that depends on the data. Porting to HLSL: usampler2D -> Texture2D<uint4>.Load, texelFetch ->
// Load(int3(p, 0)), roundEven -> round, uvec4 -> uint4.
precision highp float;
precision highp int;
precision highp usampler2D;

const float NONE = -1.0e6;
uniform highp sampler2D target;     // half-resolution target disparity (filled)
uniform highp sampler2D ring;       // its 5x5 dilation
uniform usampler2D colour0, colour1, colour2, colour3;     // RGBA8UI: RGB and key alpha
uniform highp sampler2D disparity0, disparity1, disparity2, disparity3;
uniform int n;                      // sources used, 1..4
uniform vec2 offset[4];             // (du, dv) per source
uniform vec3 weight[4];             // (c, c / 1.5, c / 1000) per source, c the scaled closeness
uniform ivec2 size;                 // the sources' size (W, H)
out uvec4 outColour;

// Fetches outside the image read the clamped texel and discard it (no branch around the fetch).
bool inside(ivec2 q) {
    return all(greaterThanEqual(q, ivec2(0))) && all(lessThan(q, size));
}

uvec4 texel(usampler2D t, ivec2 q) {
    uvec4 v = texelFetch(t, clamp(q, ivec2(0), size - 1), 0);
    return inside(q) ? v : uvec4(0u);
}

float seenAt(sampler2D t, ivec2 q) {
    float v = texelFetch(t, clamp(q, ivec2(0), size - 1), 0).r;
    return inside(q) ? v : NONE;
}

uvec4 lerp7(uvec4 a, uvec4 b, uint q) {
    return ((128u - q) * a + q * b + 64u) >> 7u;
}

void tap(usampler2D colour, sampler2D disp, vec2 off, vec3 w, ivec2 block, ivec2 inBlock, float d,
         inout uvec4 sum, inout uint total) {
    vec2 m = vec2(2 * block) - d * off;
    vec2 f = floor(m);
    ivec2 i = ivec2(f);
    uvec2 q = uvec2(ivec2((m - f) * 128.0 + 0.5));
    ivec2 nearest = i + ivec2(greaterThanEqual(2u * q, uvec2(128u))) + inBlock;
    ivec2 c = i + inBlock;
    uvec4 top = lerp7(texel(colour, c), texel(colour, c + ivec2(1, 0)), q.x);
    uvec4 bottom = lerp7(texel(colour, c + ivec2(0, 1)), texel(colour, c + ivec2(1, 1)), q.x);
    uvec4 sample_ = lerp7(top, bottom, q.y);
    float seen = seenAt(disp, nearest);
    uint k = uint(max(w.x - abs(seen - d) * w.y, w.z) + 0.5);
    sum += k * sample_;
    total += k;
}

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    ivec2 block = p / 2;
    ivec2 inBlock = p - 2 * block;
    float d = texelFetch(target, block, 0).r;
    if (d <= NONE) d = texelFetch(ring, block, 0).r;
    if (d <= NONE) {
        outColour = uvec4(0u);
        return;
    }
    uvec4 sum = uvec4(0u);
    uint total = 0u;
    tap(colour0, disparity0, offset[0], weight[0], block, inBlock, d, sum, total);
    if (n > 1) tap(colour1, disparity1, offset[1], weight[1], block, inBlock, d, sum, total);
    if (n > 2) tap(colour2, disparity2, offset[2], weight[2], block, inBlock, d, sum, total);
    if (n > 3) tap(colour3, disparity3, offset[3], weight[3], block, inBlock, d, sum, total);
    float inv = 1.0 / float(max(total, 1u));
    outColour = uvec4(min(vec4(sum) * inv + 0.5, 255.0));
}
