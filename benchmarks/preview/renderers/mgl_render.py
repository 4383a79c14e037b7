"""moderngl + EGL (Mesa llvmpipe) headless renderer; benchmark + sample PNG."""
import sys, time, statistics
import numpy as np
import scene as S

VS = """#version 330
uniform mat4 u_mvp;
in vec3 in_pos; in vec3 in_nrm; in vec3 in_fcol; in vec3 in_bcol;
out vec3 v_nrm; out vec3 v_fcol; out vec3 v_bcol;
void main() {
    v_nrm = in_nrm; v_fcol = in_fcol; v_bcol = in_bcol;
    gl_Position = u_mvp * vec4(in_pos, 1.0);
}"""
FS = """#version 330
uniform vec3 u_light;      // unit direction towards the light (world space)
in vec3 v_nrm; in vec3 v_fcol; in vec3 v_bcol;
out vec4 f_color;
void main() {
    vec3 n = normalize(v_nrm);
    vec3 col = v_fcol;
    if (!gl_FrontFacing) { n = -n; col = v_bcol; }   // double-sided: flip normal, 2nd colour
    float lam = max(dot(n, u_light), 0.0);
    f_color = vec4(col * (0.25 + 0.75 * lam), 1.0);
}"""

class Renderer:
    def __init__(self, w, h, samples=0):
        import moderngl
        self.w, self.h = w, h
        self.ctx = ctx = moderngl.create_context(standalone=True, backend='egl')
        self.prog = ctx.program(vertex_shader=VS, fragment_shader=FS)
        self.prog['u_light'].value = tuple(S.LIGHT_DIR.astype(float))
        self.prog['u_mvp'].write(S.mvp(w, h).T.copy())     # GL wants column-major
        self.samples = samples
        if samples:
            self.fbo = ctx.framebuffer(ctx.renderbuffer((w, h), 3, samples=samples),
                                       ctx.depth_renderbuffer((w, h), samples=samples))
            self.resolve = ctx.framebuffer(ctx.renderbuffer((w, h), 3))
        else:
            self.fbo = ctx.framebuffer(ctx.renderbuffer((w, h), 3), ctx.depth_renderbuffer((w, h)))
            self.resolve = self.fbo
        self.meshes = {}

    def _mesh(self, name, V, N, F, fcol, bcol):
        """Create (first time) or update (every frame) a mesh. Colours/indices only on creation."""
        pn = np.hstack([V, N]).astype('f4')
        m = self.meshes.get(name)
        if m is None or m['n'] != len(V):
            ctx = self.ctx
            cols = np.hstack([np.broadcast_to(fcol, V.shape), np.broadcast_to(bcol, V.shape)]).astype('f4')
            dyn = ctx.buffer(pn.tobytes(), dynamic=True)
            sta = ctx.buffer(cols.tobytes())
            ibo = ctx.buffer(F.astype('u4').tobytes())
            vao = ctx.vertex_array(self.prog, [(dyn, '3f 3f', 'in_pos', 'in_nrm'),
                                               (sta, '3f 3f', 'in_fcol', 'in_bcol')], ibo, index_element_size=4)
            self.meshes[name] = m = dict(n=len(V), dyn=dyn, vao=vao)
        else:
            m['dyn'].write(pn.tobytes())
        return m['vao']

    def render(self, sc):
        import moderngl
        cV, cN, cF = sc['cloth']; bV, bN, bF, bC = sc['boxes']; gV, gN, gF = sc['ground']
        vaos = [self._mesh('cloth', cV, cN, cF, S.ORANGE, S.BLUE),
                self._mesh('boxes', bV, bN, bF, bC, bC),
                self._mesh('ground', gV, gN, gF, S.GROUND, S.GROUND)]
        self.fbo.use()
        self.ctx.enable(moderngl.DEPTH_TEST)        # no CULL_FACE -> double-sided
        self.ctx.clear(0.82, 0.88, 0.95, 1.0, depth=1.0)
        for v in vaos:
            v.render(moderngl.TRIANGLES)
        if self.samples:
            self.ctx.copy_framebuffer(self.resolve, self.fbo)   # MSAA resolve (glBlitFramebuffer)
        raw = self.resolve.read(components=3, alignment=1)
        return np.frombuffer(raw, np.uint8).reshape(self.h, self.w, 3)[::-1]   # GL origin is bottom-left

def bench():
    from PIL import Image
    t0 = time.perf_counter()
    import moderngl
    r = Renderer(1280, 720)
    print(f"setup (import+context+program+fbo): {time.perf_counter()-t0:.3f}s")
    for samples in (0, 4):
        for which in 'AB':
            scenes = [S.scene(which, 0.1 * i) for i in range(10)]
            for (w, h) in ((1280, 720), (640, 360)):
                r = Renderer(w, h, samples)
                r.render(scenes[0])  # warm-up (shader compile, buffer alloc)
                ts = []
                for sc in scenes:
                    t = time.perf_counter(); img = r.render(sc); ts.append(time.perf_counter() - t)
                print(f"samples={samples} scene={which} {w}x{h}: median {statistics.median(ts)*1000:.1f} ms/frame")
                if which == 'A' and w == 1280:
                    Image.fromarray(img).save(f"{S.OUT}/moderngl_A{'_msaa4' if samples else ''}.png")
                r.ctx.release()

if __name__ == '__main__':
    bench()
