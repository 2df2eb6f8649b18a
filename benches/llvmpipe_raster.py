#!/usr/bin/env python3
"""Mesa llvmpipe (OpenGL 3.3 through moderngl, headless EGL) on the scene of
chiaro-raster's `raster_bench` example: a 14x14 grid of icospheres (the
icosahedron subdivided 4 times, radius 0.45: 1,003,520 triangles), 1920x1080,
depth test, two point lights and ambient, Phong model (R.V)^32.

Modes: phong (per-pixel), gouraud (per-vertex), flat (per-pixel with the
face normal from screen derivatives). Prints ms/frame, median of FRAMES after
3 warm-up frames, wall and process CPU time (all of llvmpipe's threads).
Builds the mesh itself (no trimesh).

usage: LIBGL_ALWAYS_SOFTWARE=1 llvmpipe_raster.py [phong|gouraud|flat] [FRAMES] [cull 0|1]
"""
import os
import sys
import time

import moderngl
import numpy as np

mode = sys.argv[1] if len(sys.argv) > 1 else "phong"
frames = int(sys.argv[2]) if len(sys.argv) > 2 else 5
cull = (sys.argv[3] if len(sys.argv) > 3 else "1") == "1"
W, H = 1920, 1080


def icosphere(radius, levels):
    """Same construction as raster_bench.rs: unit icosahedron, 4-way splits."""
    t = (1 + 5 ** 0.5) / 2
    p = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    p = [np.array(v, np.float64) / np.linalg.norm(v) for v in p]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
         [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    for _ in range(levels):
        mid = {}

        def m(a, b):
            k = (min(a, b), max(a, b))
            if k not in mid:
                q = (p[a] + p[b]) / 2
                p.append(q / np.linalg.norm(q))
                mid[k] = len(p) - 1
            return mid[k]

        nf = []
        for a, b, c in f:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            nf += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = nf
    n = np.array(p, np.float32)
    return n * radius, n, np.array(f, np.uint32)


V0, N0, F0 = icosphere(0.45, 4)
Vs, Ns, Fs = [], [], []
k = 0
for i in range(14):
    for j in range(14):
        Vs.append(V0 + np.array([i - 6.5, j - 6.5, 0], np.float32))
        Ns.append(N0)
        Fs.append(F0 + k * len(V0))
        k += 1
V, Nn, F = np.concatenate(Vs), np.concatenate(Ns), np.concatenate(Fs).astype(np.uint32)


def perspective(fovy, aspect, n, f):
    t = 1 / np.tan(fovy / 2)
    return np.array([[t / aspect, 0, 0, 0], [0, t, 0, 0], [0, 0, (f + n) / (n - f), 2 * f * n / (n - f)],
                     [0, 0, -1, 0]], np.float32)


def look_at(eye, at, up):
    f = at - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    M = np.eye(4, dtype=np.float32)
    M[0, :3], M[1, :3], M[2, :3] = s, u, -f
    M[:3, 3] = -M[:3, :3] @ eye
    return M


ctx = moderngl.create_standalone_context(backend="egl")
print("GL_RENDERER:", ctx.info["GL_RENDERER"], "| GL_VERSION:", ctx.info["GL_VERSION"],
      "| LP_NUM_THREADS:", os.environ.get("LP_NUM_THREADS", "(default)"))
print(f"mesh: {len(F)} triangles, {len(V)} vertices; cull back faces: {cull}")
eye = np.array([0, -4.5, 8], np.float32)
MV = look_at(eye, np.zeros(3, np.float32), np.array([0, 0, 1], np.float32))
P = perspective(np.radians(60), W / H, 0.1, 100)

PHONG = """
uniform vec3 L0; uniform vec3 L1;
vec3 phong(vec3 p, vec3 n, vec3 L, vec3 c){ vec3 l = normalize(L-p); vec3 v = normalize(-p); vec3 r = reflect(-l,n);
  float d = max(dot(n,l),0.0);
  return c*d*vec3(0.7,0.3,0.2) + (d > 0.0 ? c*pow(max(dot(r,v),0.0),32.0) : vec3(0.0)); }
vec3 shade(vec3 p, vec3 n){ return vec3(0.1,0.1167,0.175) + phong(p,n,L0,vec3(0.8)) + phong(p,n,L1,vec3(0.4)); }
"""
VS_PIXEL = """#version 330
uniform mat4 MV; uniform mat4 P; in vec3 in_pos; in vec3 in_nrm; out vec3 v_pos; out vec3 v_nrm;
void main(){ vec4 p = MV*vec4(in_pos,1); v_pos = p.xyz; v_nrm = mat3(MV)*in_nrm; gl_Position = P*p; }"""
FS_PHONG = "#version 330\n" + PHONG + """in vec3 v_pos; in vec3 v_nrm; out vec4 frag;
void main(){ frag = vec4(pow(shade(v_pos, normalize(v_nrm)), vec3(1.0/2.2)),1); }"""
FS_FLAT = "#version 330\n" + PHONG + """in vec3 v_pos; in vec3 v_nrm; out vec4 frag;
void main(){ vec3 n = normalize(cross(dFdx(v_pos), dFdy(v_pos)));
  frag = vec4(pow(shade(v_pos, n), vec3(1.0/2.2)),1); }"""
VS_GOURAUD = "#version 330\n" + PHONG + """uniform mat4 MV; uniform mat4 P;
in vec3 in_pos; in vec3 in_nrm; out vec3 v_col;
void main(){ vec4 p = MV*vec4(in_pos,1); v_col = shade(p.xyz, normalize(mat3(MV)*in_nrm)); gl_Position = P*p; }"""
FS_GOURAUD = """#version 330
in vec3 v_col; out vec4 frag; void main(){ frag = vec4(pow(v_col, vec3(1.0/2.2)),1); }"""

vs, fs = {"phong": (VS_PIXEL, FS_PHONG), "flat": (VS_PIXEL, FS_FLAT), "gouraud": (VS_GOURAUD, FS_GOURAUD)}[mode]
prog = ctx.program(vertex_shader=vs, fragment_shader=fs)
prog["MV"].write(MV.T.copy().tobytes())
prog["P"].write(P.T.copy().tobytes())
L0 = (MV @ np.array([5, -5, 10, 1], np.float32))[:3]
L1 = (MV @ np.array([-8, 2, 6, 1], np.float32))[:3]
prog["L0"].value = tuple(float(x) for x in L0)
prog["L1"].value = tuple(float(x) for x in L1)
vbo = ctx.buffer(np.hstack([V, Nn]).astype(np.float32).tobytes())
ibo = ctx.buffer(F.tobytes())
attrs = ["in_pos", "in_nrm"] if "in_nrm" in prog else ["in_pos"]
layout = "3f 3f" if len(attrs) == 2 else "3f 12x"
vao = ctx.vertex_array(prog, [(vbo, layout, *attrs)], index_buffer=ibo, index_element_size=4)
fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((W, H), 4)], depth_attachment=ctx.depth_renderbuffer((W, H)))
fbo.use()
ctx.enable(moderngl.DEPTH_TEST)
if cull:
    ctx.enable(moderngl.CULL_FACE)  # counter-clockwise fronts, as chiaro's meshes
else:
    ctx.disable(moderngl.CULL_FACE)


def frame():
    fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
    vao.render(moderngl.TRIANGLES)
    ctx.finish()


for _ in range(3):
    frame()
wall, cpu = [], []
for _ in range(frames):
    a, c = time.perf_counter(), time.process_time()
    frame()
    wall.append((time.perf_counter() - a) * 1e3)
    cpu.append((time.process_time() - c) * 1e3)
wall.sort()
cpu.sort()
img = np.frombuffer(fbo.read(components=3), np.uint8).reshape(H, W, 3)[::-1]
print(f"llvmpipe {mode}: median {wall[len(wall) // 2]:.1f} ms/frame (min {wall[0]:.1f}, max {wall[-1]:.1f}, "
      f"n={frames}); cpu {cpu[len(cpu) // 2]:.0f} ms/frame; covered {(img.sum(2) > 0).mean() * 100:.1f}%")
out = os.environ.get("PEERS_OUT")
if out:
    try:
        from PIL import Image
        Image.fromarray(img).save(os.path.join(out, f"llvmpipe_{mode}.png"))
    except ImportError:
        pass
