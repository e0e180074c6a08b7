#version 300 es
// Step 1a: the point's disparity, blended into the target with MAX.
precision highp float;
in float vDisparity;
out float outDisparity;
void main() {
    outDisparity = vDisparity;
}
