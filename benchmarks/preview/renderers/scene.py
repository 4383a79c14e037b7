"""Shared test scenes + camera math for the renderer evaluation (numpy only).

Scene A: a 64 x 64 grid cloth (8k triangles) rolled over itself, six boxes, a ground quad;
scene B: a 257 x 257 cloth (131k triangles) and 1,000 small boxes (12k triangles).
Images go to $RENDERER_EVAL_OUT (default: the temp directory).
"""
import os
import tempfile

import numpy as np

OUT = os.environ.get("RENDERER_EVAL_OUT", tempfile.gettempdir())

ORANGE = (1.0, 0.55, 0.1); BLUE = (0.15, 0.35, 1.0); GROUND = (0.6, 0.6, 0.6)
EYE = np.array([3.2, 2.6, 3.6]); TARGET = np.array([0.9, 0.35, 0.9]); UP = np.array([0., 1., 0.])
FOVY = 40.0
LIGHT_DIR = np.array([0.4, 1.0, 0.3]) / np.linalg.norm([0.4, 1.0, 0.3])  # direction TO the light

def vertex_normals(V, F):
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    N = np.zeros_like(V)
    for k in range(3):
        np.add.at(N, F[:, k], fn)
    N /= np.linalg.norm(N, axis=1, keepdims=True) + 1e-12
    return N

def grid_faces(n):
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing='ij')
    a = (i * n + j).ravel(); b = a + n; c = a + 1; d = b + 1
    # CCW seen from +y (front = top of the flat part)
    return np.concatenate([np.stack([a, c, b], 1), np.stack([c, d, b], 1)]).astype(np.uint32)

def cloth(n, t=0.0):
    """n x n vertex cloth, 2 m x 2 m, flat part + a curl that rolls over itself (shows back side)."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing='ij')
    L = 2.6; s = u * L; s0 = 1.0; r = 0.28 + 0.03 * np.sin(t)
    th = np.clip((s - s0) / r, 0, None)
    th = np.minimum(th, 1.35 * np.pi)
    extra = np.clip(s - s0 - 1.35 * np.pi * r, 0, None)
    x = np.where(s < s0, s, s0 + r * np.sin(th) + extra * np.cos(1.35 * np.pi))
    y = np.where(s < s0, 0.45, 0.45 + r * (1 - np.cos(th)) + extra * np.sin(1.35 * np.pi))
    y = y + 0.06 * np.sin(7 * v * np.pi + t) * (0.3 + u)
    z = v * 2.0 + 0.05 * np.sin(5 * u * np.pi + t)
    V = np.stack([x, y, z], -1).reshape(-1, 3).astype(np.float32)
    F = grid_faces(n)
    return V, F

_BOX_F = np.array([[0,1,2],[0,2,3]], np.uint32)
def boxes(centers, sizes):
    """Flat-shaded boxes: 24 verts / 12 tris each, outward CCW winding."""
    dirs = np.array([[1,0,0],[-1,0,0],[0,1,0],[0,-1,0],[0,0,1],[0,0,-1]], np.float32)
    quads = []
    for d in dirs:
        a = np.roll(d, 1); b = np.cross(d, a)
        quads.append([d - a - b, d + a - b, d + a + b, d - a + b])
    q = np.array(quads, np.float32).reshape(24, 3) * 0.5          # unit box corners
    qn = np.repeat(dirs, 4, 0)
    nb = len(centers)
    V = (q[None] * sizes[:, None, :] + centers[:, None, :]).reshape(-1, 3)
    N = np.broadcast_to(qn, (nb, 24, 3)).reshape(-1, 3)
    Fq = np.concatenate([_BOX_F + 4 * k for k in range(6)])
    F = (Fq[None] + 24 * np.arange(nb)[:, None, None]).reshape(-1, 3).astype(np.uint32)
    # fix winding so it is CCW w.r.t. the outward normal
    e = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    bad = (e * N[F[:, 0]]).sum(1) < 0
    F[bad] = F[bad][:, [0, 2, 1]]
    return V.astype(np.float32), N.astype(np.float32), F

def box_set(which, t=0.0):
    rng = np.random.default_rng(1)
    if which == 'A':
        c = np.array([[-0.6,0.2,0.3],[-0.6,0.15,1.5],[0.4,0.25,2.6],[2.6,0.3,0.2],[2.4,0.2,2.5],[1.2,0.1,-0.6]], np.float32)
        s = np.array([[0.4,0.4,0.4],[0.3,0.3,0.6],[0.5,0.5,0.3],[0.5,0.6,0.5],[0.4,0.4,0.4],[0.8,0.2,0.3]], np.float32)
        c[:, 1] = s[:, 1] / 2
    else:
        c = rng.uniform([-1.5, 0, -1.5], [3.5, 0, 3.5], (1000, 3)).astype(np.float32)
        s = rng.uniform(0.04, 0.12, (1000, 3)).astype(np.float32)
        c[:, 1] = s[:, 1] / 2 + 0.02 * np.sin(t + np.arange(1000))[:] ** 2
    cols = rng.uniform(0.2, 0.9, (len(c), 3)).astype(np.float32)
    V, N, F = boxes(c, s)
    C = np.repeat(cols, 24, 0)
    return V, N, F, C

def ground():
    V = np.array([[-6,0,-6],[6,0,-6],[6,0,6],[-6,0,6]], np.float32)
    N = np.tile(np.float32([0,1,0]), (4,1))
    F = np.array([[0,2,1],[0,3,2]], np.uint32)
    return V, N, F

def scene(which, t=0.0):
    n = 64 if which == 'A' else 257
    cV, cF = cloth(n, t)
    cN = vertex_normals(cV, cF)
    bV, bN, bF, bC = box_set(which, t)
    gV, gN, gF = ground()
    return dict(cloth=(cV, cN, cF), boxes=(bV, bN, bF, bC), ground=(gV, gN, gF))

def look_at(eye, target, up):
    f = target - eye; f = f / np.linalg.norm(f)
    s = np.cross(f, up); s /= np.linalg.norm(s); u = np.cross(s, f)
    M = np.eye(4); M[0, :3] = s; M[1, :3] = u; M[2, :3] = -f
    M[:3, 3] = -M[:3, :3] @ eye
    return M

def perspective(fovy, aspect, near=0.05, far=50.0):
    f = 1 / np.tan(np.radians(fovy) / 2)
    P = np.zeros((4, 4)); P[0, 0] = f / aspect; P[1, 1] = f
    P[2, 2] = (far + near) / (near - far); P[2, 3] = 2 * far * near / (near - far); P[3, 2] = -1
    return P

def mvp(w, h):
    return (perspective(FOVY, w / h) @ look_at(EYE, TARGET, UP)).astype(np.float32)
