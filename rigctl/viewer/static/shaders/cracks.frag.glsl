#version 300 es
// Step 1c: holes of the splatted target take its 3x3 closing where that has a value (one-pixel cracks).
precision highp float;
precision highp int;

const float NONE = -1.0e6;
uniform highp sampler2D splatted;
uniform highp sampler2D closed;
out float outDisparity;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    float d = texelFetch(splatted, p, 0).r;
    outDisparity = d > NONE ? d : texelFetch(closed, p, 0).r;
}
