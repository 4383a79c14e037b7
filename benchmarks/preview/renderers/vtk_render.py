"""VTK offscreen renderer (pip vtk wheel; EGL or OSMesa chosen at runtime); benchmark + sample PNG."""
import os, sys, time, statistics
import numpy as np
import scene as S

class Renderer:
    def __init__(self, w, h, aa=None):
        import vtk
        from vtk.util import numpy_support as ns
        self.vtk, self.ns, self.w, self.h = vtk, ns, w, h
        self.ren = vtk.vtkRenderer(); self.ren.SetBackground(0.82, 0.88, 0.95)
        self.ren.AutomaticLightCreationOff()
        L = vtk.vtkLight(); L.SetLightTypeToSceneLight(); L.SetPositional(False)
        L.SetPosition(*S.LIGHT_DIR); L.SetFocalPoint(0, 0, 0); L.SetIntensity(1.0)
        self.ren.AddLight(L)
        if aa == 'fxaa':
            self.ren.UseFXAAOn()
        self.win = vtk.vtkRenderWindow(); self.win.SetOffScreenRendering(1)
        self.win.SetMultiSamples(4 if aa == 'msaa4' else 0)
        self.win.AddRenderer(self.ren); self.win.SetSize(w, h)
        cam = self.ren.GetActiveCamera()
        cam.SetPosition(*S.EYE); cam.SetFocalPoint(*S.TARGET); cam.SetViewUp(*S.UP); cam.SetViewAngle(S.FOVY)
        cam.SetClippingRange(0.05, 50)
        self.objs = {}
        self.buf = vtk.vtkUnsignedCharArray()

    def _obj(self, name, V, N, F, colors=None, front=None, back=None):
        vtk, ns = self.vtk, self.ns
        o = self.objs.get(name)
        if o is None or o['n'] != len(V):
            pd = vtk.vtkPolyData()
            pts = vtk.vtkPoints(); pd.SetPoints(pts)
            cells = vtk.vtkCellArray()
            off = np.arange(0, 3 * len(F) + 1, 3, dtype=np.int64)
            cells.SetData(ns.numpy_to_vtk(off, deep=1, array_type=vtk.VTK_ID_TYPE),
                          ns.numpy_to_vtk(F.astype(np.int64).ravel(), deep=1, array_type=vtk.VTK_ID_TYPE))
            pd.SetPolys(cells)
            if colors is not None:
                c = ns.numpy_to_vtk((np.asarray(colors) * 255).astype(np.uint8), deep=1); c.SetName('rgb')
                pd.GetPointData().SetScalars(c)
            m = vtk.vtkPolyDataMapper(); m.SetInputData(pd)
            if colors is not None:
                m.SetColorModeToDirectScalars(); m.ScalarVisibilityOn()
            else:
                m.ScalarVisibilityOff()
            a = vtk.vtkActor(); a.SetMapper(m)
            p = a.GetProperty(); p.SetAmbient(0.25); p.SetDiffuse(0.75); p.SetSpecular(0.0)
            if front is not None: p.SetColor(*front)
            if back is not None:
                bp = vtk.vtkProperty(); bp.DeepCopy(p); bp.SetColor(*back); a.SetBackfaceProperty(bp)
            self.ren.AddActor(a)
            self.objs[name] = o = dict(n=len(V), pd=pd, pts=pts)
        pd = o['pd']
        o['pts'].SetData(ns.numpy_to_vtk(V, deep=1))
        nrm = ns.numpy_to_vtk(np.ascontiguousarray(N, dtype=np.float32), deep=1); nrm.SetName('Normals')
        pd.GetPointData().SetNormals(nrm)
        pd.Modified()

    def render(self, sc):
        cV, cN, cF = sc['cloth']; bV, bN, bF, bC = sc['boxes']; gV, gN, gF = sc['ground']
        self._obj('cloth', cV, cN, cF, front=S.ORANGE, back=S.BLUE)
        self._obj('boxes', bV, bN, bF, colors=bC)
        self._obj('ground', gV, gN, gF, front=S.GROUND)
        self.win.Render()
        self.win.GetPixelData(0, 0, self.w - 1, self.h - 1, 0, self.buf, 0)   # back buffer
        return self.ns.vtk_to_numpy(self.buf).reshape(self.h, self.w, 3)[::-1]

def bench(aas):
    from PIL import Image
    t0 = time.perf_counter()
    import vtk
    r = Renderer(1280, 720); r.win.Render()
    print(f"setup (import+window+first Render): {time.perf_counter()-t0:.3f}s  window class: {r.win.GetClassName()}")
    print(r.win.ReportCapabilities().splitlines()[:3])
    for aa in aas:
        for which in 'AB':
            scenes = [S.scene(which, 0.1 * i) for i in range(10)]
            for (w, h) in ((1280, 720), (640, 360)):
                r = Renderer(w, h, aa); r.render(scenes[0])
                ts = []
                for sc in scenes:
                    t = time.perf_counter(); img = r.render(sc); ts.append(time.perf_counter() - t)
                print(f"aa={aa} scene={which} {w}x{h}: median {statistics.median(ts)*1000:.1f} ms/frame", flush=True)
                if which == 'A' and w == 1280:
                    Image.fromarray(np.ascontiguousarray(img)).save(f"{S.OUT}/vtk_A{'_'+aa if aa else ''}.png")
                r.win.Finalize()

if __name__ == '__main__':
    bench([None if a == 'none' else a for a in (sys.argv[1:] or ['none'])])
