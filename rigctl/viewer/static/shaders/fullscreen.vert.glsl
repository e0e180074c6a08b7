#version 300 es
// One triangle over the whole target, made from gl_VertexID (no vertex buffer). Every pass but the splat
// uses it; the fragment's pixel is ivec2(gl_FragCoord.xy), row 0 being the image's first row.
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(p, 0.0, 1.0);
}
