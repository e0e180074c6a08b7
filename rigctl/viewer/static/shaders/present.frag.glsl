#version 300 es
// On screen only: a rendered view (RGBA8UI, straight alpha) over a grey checkerboard, flipped so that the
// image's first row is at the top. The read-back for tests and the benchmark takes the view itself.
precision highp float;
precision highp int;
precision highp usampler2D;

uniform usampler2D view;
uniform ivec4 viewport;             // x, y, width, height of this eye on the canvas
out vec4 outColour;

void main() {
    ivec2 size = textureSize(view, 0);
    ivec2 p = ivec2(gl_FragCoord.xy) - viewport.xy;
    ivec2 q = ivec2(p.x * size.x / viewport.z, size.y - 1 - p.y * size.y / viewport.w);
    vec4 c = vec4(texelFetch(view, q, 0)) / 255.0;
    float check = ((p.x / 16 + p.y / 16) % 2 == 0) ? 0.30 : 0.38;
    outColour = vec4(mix(vec3(check), c.rgb, c.a), 1.0);
}
