"""GLSL programs of the overlay renderer (GLSL 3.30 core: OSMesa gives a 3.3 context, EGL 4.1) and their compilation.

All colour outputs are premultiplied RGBA (blending GL_ONE, GL_ONE_MINUS_SRC_ALPHA).
"""

from __future__ import annotations

from OpenGL import GL

SURFACE_VS = """
#version 330 core
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec3 a_nrm;
uniform mat4 u_mv;     // GL camera from model
uniform mat4 u_proj;
uniform mat3 u_nmat;   // normal matrix (inverse transpose of u_mv's 3x3)
out vec3 v_pos;
out vec3 v_nrm;
void main() {
    vec4 p = u_mv * vec4(a_pos, 1.0);
    v_pos = p.xyz;
    v_nrm = u_nmat * a_nrm;
    gl_Position = u_proj * p;
}
"""

# Headlight (light at the camera) + ambient, two-sided: an open NURBS patch shows both sides.
SURFACE_FS = """
#version 330 core
in vec3 v_pos;
in vec3 v_nrm;
uniform vec4 u_color;     // straight RGBA
uniform float u_ambient;
out vec4 frag;
// x^24 by squaring: a CPU rasteriser (llvmpipe) evaluates pow() as exp2(24 log2 x), which costs
// more than the rest of the shader; the products give the same 8-bit colours
float pow24(float x) {
    float x2 = x * x;
    float x4 = x2 * x2;
    float x8 = x4 * x4;
    return x8 * x8 * x8;
}
void main() {
    vec3 n = normalize(v_nrm);
    vec3 v = normalize(-v_pos);
    float d = abs(dot(n, v));
    float spec = 0.25 * pow24(max(2.0 * d * d - 1.0, 0.0));
    vec3 c = u_color.rgb * (u_ambient + (1.0 - u_ambient) * d) + vec3(spec);
    frag = vec4(min(c, vec3(1.0)) * u_color.a, u_color.a);
}
"""

LINE_VS = """
#version 330 core
layout(location = 0) in vec3 a_pos;
uniform mat4 u_mv;
uniform mat4 u_proj;
void main() { gl_Position = u_proj * (u_mv * vec4(a_pos, 1.0)); }
"""

# Wide lines in a core profile: each segment becomes a screen-space quad of u_width pixels,
# clipped at the near plane first (w is the OpenCV depth z) so a segment behind the camera
# never flips across the screen.
LINE_GS = """
#version 330 core
layout(lines) in;
layout(triangle_strip, max_vertices = 4) out;
uniform vec2 u_viewport;   // crop size in pixels
uniform float u_width;     // line width in pixels
uniform float u_near;
void main() {
    vec4 a = gl_in[0].gl_Position;
    vec4 b = gl_in[1].gl_Position;
    if (a.w < u_near && b.w < u_near) return;
    if (a.w < u_near) a = mix(a, b, (u_near - a.w) / (b.w - a.w));
    if (b.w < u_near) b = mix(b, a, (u_near - b.w) / (a.w - b.w));
    vec2 sa = a.xy / a.w * 0.5 * u_viewport;
    vec2 sb = b.xy / b.w * 0.5 * u_viewport;
    vec2 d = sb - sa;
    float len = length(d);
    d = len > 1e-6 ? d / len : vec2(1.0, 0.0);
    vec2 n = vec2(-d.y, d.x) * (0.5 * u_width);
    vec2 e = d * (0.5 * u_width);           // square caps close the joints of polylines
    vec2 to_ndc = 2.0 / u_viewport;
    gl_Position = vec4((sa - e + n) * to_ndc * a.w, a.z, a.w); EmitVertex();
    gl_Position = vec4((sa - e - n) * to_ndc * a.w, a.z, a.w); EmitVertex();
    gl_Position = vec4((sb + e + n) * to_ndc * b.w, b.z, b.w); EmitVertex();
    gl_Position = vec4((sb + e - n) * to_ndc * b.w, b.z, b.w); EmitVertex();
    EndPrimitive();
}
"""

FLAT_FS = """
#version 330 core
uniform vec4 u_color;   // premultiplied RGBA
out vec4 frag;
void main() { frag = u_color; }
"""

# Contact shadow: a quad on the anchor plane textured with a blurred footprint (alpha only).
SHADOW_VS = """
#version 330 core
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec2 a_uv;
uniform mat4 u_mv;
uniform mat4 u_proj;
out vec2 v_uv;
void main() { v_uv = a_uv; gl_Position = u_proj * (u_mv * vec4(a_pos, 1.0)); }
"""

SHADOW_FS = """
#version 330 core
in vec2 v_uv;
uniform sampler2D u_tex;
uniform float u_opacity;
out vec4 frag;
void main() { float a = texture(u_tex, v_uv).r * u_opacity; frag = vec4(0.0, 0.0, 0.0, a); }
"""


class _Uniforms(dict):
    """Uniform locations; a uniform the GLSL compiler optimised away maps to -1 (setting it is a no-op)."""

    def __missing__(self, key):
        return -1


def _compile(src: str, kind) -> int:
    sh = GL.glCreateShader(kind)
    GL.glShaderSource(sh, src)
    GL.glCompileShader(sh)
    if not GL.glGetShaderiv(sh, GL.GL_COMPILE_STATUS):
        log = GL.glGetShaderInfoLog(sh)
        raise RuntimeError(f"GLSL compile error: {log!r}")
    return sh


def build_program(vs: str, fs: str, gs: str | None = None) -> tuple[int, dict]:
    """Linked program id and a dict of its uniform locations."""
    prog = GL.glCreateProgram()
    shaders = [_compile(vs, GL.GL_VERTEX_SHADER), _compile(fs, GL.GL_FRAGMENT_SHADER)]
    if gs is not None:
        shaders.append(_compile(gs, GL.GL_GEOMETRY_SHADER))
    for sh in shaders:
        GL.glAttachShader(prog, sh)
    GL.glLinkProgram(prog)
    if not GL.glGetProgramiv(prog, GL.GL_LINK_STATUS):
        raise RuntimeError(f"GLSL link error: {GL.glGetProgramInfoLog(prog)!r}")
    for sh in shaders:
        GL.glDeleteShader(sh)
    uniforms = _Uniforms()
    n = GL.glGetProgramiv(prog, GL.GL_ACTIVE_UNIFORMS)
    for i in range(n):
        name = GL.glGetActiveUniform(prog, i)[0]
        name = name.decode() if isinstance(name, bytes) else name
        uniforms[name] = GL.glGetUniformLocation(prog, name)
    return prog, uniforms
