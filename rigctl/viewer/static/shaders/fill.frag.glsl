#version 300 es
// Step 1d, fill (rigctl.render.kernels.close_and_fill): a hole between two disparities at most maxGap apart
// along the axis takes the smaller of the two -- the background side of a disocclusion. Rows first, then
// columns of the row-filled result, as the CPU pass does in one sweep.
precision highp float;
precision highp int;

const float NONE = -1.0e6;
const float FAR = 1.0e9;
uniform highp sampler2D source;     // the disparity
uniform highp sampler2D ends;       // scan.frag's result along the same axis
uniform ivec2 axis;
uniform int maxGap;
out float outDisparity;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    float d = texelFetch(source, p, 0).r;
    vec2 e = texelFetch(ends, p, 0).rg;
    if (d <= NONE && e.x >= 0.0 && e.y < FAR && e.y - e.x <= float(maxGap)) {
        ivec2 a = axis.x == 1 ? ivec2(int(e.x), p.y) : ivec2(p.x, int(e.x));
        ivec2 b = axis.x == 1 ? ivec2(int(e.y), p.y) : ivec2(p.x, int(e.y));
        d = min(texelFetch(source, a, 0).r, texelFetch(source, b, 0).r);
    }
    outDisparity = d;
}
