"""Mitsuba 3 CPU renderer: seconds per frame at low spp. usage: mi_render.py VARIANT"""
import os, sys, time, statistics
import numpy as np
import scene as S

VARIANT = sys.argv[1] if len(sys.argv) > 1 else 'scalar_rgb'
SPPS = [int(x) for x in (sys.argv[2].split(',') if len(sys.argv) > 2 else ['4', '16'])]

class Renderer:
    def __init__(self, w, h):
        import mitsuba as mi
        mi.set_variant(VARIANT)
        self.mi, self.w, self.h = mi, w, h
        self.scene = None; self.sig = None

    def render(self, sc, spp):
        mi = self.mi
        cV, cN, cF = sc['cloth']; bV, bN, bF, bC = sc['boxes']
        if self.scene is None:
            self.scene = mi.load_dict(scene_dict(mi, sc, self.w, self.h))
            self.params = mi.traverse(self.scene)
        else:
            P = self.params
            for k, arr in (('cloth.vertex_positions', cV), ('cloth.vertex_normals', cN),
                           ('boxes.vertex_positions', bV), ('boxes.vertex_normals', bN)):
                P[k] = type(P[k])(np.ravel(arr).astype(np.float32))
            P.update()   # rebuilds the BVH
        img = mi.render(self.scene, spp=spp, seed=0)
        rgb = np.array(mi.Bitmap(img).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True))
        return rgb

def scene_dict(mi, sc, w, h):
    """Meshes are written to PLY files once (topology), then vertex data is updated via traverse() per frame."""
    def diffuse(c): return {'type': 'diffuse', 'reflectance': {'type': 'rgb', 'value': list(c)}}
    d = {'type': 'scene', 'integrator': {'type': 'direct'},
         'sensor': {'type': 'perspective', 'fov': S.FOVY, 'fov_axis': 'y',
                    'to_world': mi.ScalarTransform4f().look_at(origin=list(map(float, S.EYE)), target=list(map(float, S.TARGET)), up=[0, 1, 0]),
                    'film': {'type': 'hdrfilm', 'width': w, 'height': h, 'rfilter': {'type': 'box'}, 'pixel_format': 'rgb'},
                    'sampler': {'type': 'independent'}},
         'sun': {'type': 'directional', 'direction': list(map(float, -S.LIGHT_DIR)), 'irradiance': {'type': 'rgb', 'value': 2.4}},
         'sky': {'type': 'constant', 'radiance': {'type': 'rgb', 'value': [0.25, 0.25, 0.25]}}}
    cV, cN, cF = sc['cloth']; bV, bN, bF, bC = sc['boxes']; gV, gN, gF = sc['ground']
    for name, (V, N, F), bsdf, C in [
            ('cloth', (cV, cN, cF), {'type': 'twosided', 'a': diffuse(S.ORANGE), 'b': diffuse(S.BLUE)}, None),
            ('boxes', (bV, bN, bF), {'type': 'diffuse', 'reflectance': {'type': 'mesh_attribute', 'name': 'vertex_color'}}, bC),
            ('ground', (gV, gN, gF), diffuse(S.GROUND), None)]:
        m = mi.Mesh(name, len(V), len(F), has_vertex_normals=True, props=mi.Properties())
        p = mi.traverse(m)
        T = type(p['vertex_positions'])
        if C is not None:
            m.add_attribute('vertex_color', 3, T(np.asarray(C, np.float32).ravel()))
        p['vertex_positions'] = T(np.ravel(V).astype(np.float32))
        p['vertex_normals'] = T(np.ravel(N).astype(np.float32))
        p['faces'] = type(p['faces'])(np.ravel(F).astype(np.uint32))
        p.update()
        path = f'{S.OUT}/mi_{name}_{len(V)}.ply'
        m.write_ply(path)
        d[name] = {'type': 'ply', 'filename': path, 'bsdf': bsdf, 'face_normals': False}
    return d

def bench():
    from PIL import Image
    t0 = time.perf_counter()
    import mitsuba as mi
    mi.set_variant(VARIANT)
    print(f"import+set_variant({VARIANT}): {time.perf_counter()-t0:.3f}s", flush=True)
    nfr = int(os.environ.get('NFR', '10'))
    for which in 'AB':
        scenes = [S.scene(which, 0.1 * i) for i in range(nfr)]
        for (w, h) in ((1280, 720), (640, 360)):
            for spp in SPPS:
                r = Renderer(w, h)
                t = time.perf_counter(); img = r.render(scenes[0], spp)
                print(f"  first frame (scene load + JIT) {time.perf_counter()-t:.2f}s", flush=True)
                ts = []
                for sc in scenes:
                    t = time.perf_counter(); img = r.render(sc, spp); ts.append(time.perf_counter() - t)
                print(f"{VARIANT} scene={which} {w}x{h} spp={spp}: median {statistics.median(ts):.3f} s/frame (n={len(ts)})", flush=True)
                if which == 'A' and w == 1280:
                    Image.fromarray(img).save(f"{S.OUT}/mitsuba_{VARIANT}_A_spp{spp}.png")

if __name__ == '__main__':
    bench()
