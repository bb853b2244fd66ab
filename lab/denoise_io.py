"""Where a denoised frame's time goes around the filter, on the GPU machine: the read-back from GL,
the copies to and from OIDN's device, the upload of the result; each way of doing them.
Run: source lab/device.sh && python3 lab/denoise_io.py  (findings: docs/experiments.md)."""
import statistics
import time

import moderngl
import numpy as np
import pyoidn
from pyoidn.capi import oidn_ffi


def ms(f, n=7):
    f()
    out = []
    for _ in range(n):
        t = time.perf_counter()
        f()
        out.append(1e3 * (time.perf_counter() - t))
    return statistics.median(out)


def view(buf, nbytes):
    return np.frombuffer(oidn_ffi.buffer(buf.get_data(), nbytes), np.float32)


ctx = moderngl.create_standalone_context(backend="egl", require=430)
dev = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CUDA)
dev.commit()
for w, h in ((512, 512), (1920, 1080)):
    rgba_bytes, rgb_bytes = w * h * 16, w * h * 12
    tex = ctx.texture((w, h), 4, dtype="f4")
    tex.write(np.random.default_rng(0).exponential(1, (h, w, 4)).astype(np.float32).tobytes())
    out_tex = ctx.texture((w, h), 3, dtype="f4")
    row = {"size": f"{w}x{h}"}
    pageable = np.empty(w * h * 4, np.float32)
    row["gl read() bytes"] = ms(lambda: (tex.read(), ctx.finish()))
    row["gl read_into pageable"] = ms(lambda: tex.read_into(pageable))
    host = pyoidn.Buffer(dev, rgba_bytes, storage=pyoidn.OIDN_STORAGE_HOST)
    pinned = view(host, rgba_bytes)
    row["gl read_into pinned"] = ms(lambda: tex.read_into(pinned))
    pbo = ctx.buffer(reserve=rgba_bytes)
    row["gl read_into pbo + pbo.read_into pinned"] = ms(lambda: (tex.read_into(pbo), pbo.read_into(pinned)))
    # guides resident on the device
    albedo = pyoidn.Buffer(dev, rgb_bytes)
    normal = pyoidn.Buffer(dev, rgb_bytes)
    albedo.write(0, rgb_bytes, np.full(w * h * 3, 0.5, np.float32))
    normal.write(0, rgb_bytes, np.zeros(w * h * 3, np.float32))
    for label, storage in (("device", pyoidn.OIDN_STORAGE_DEVICE), ("host", pyoidn.OIDN_STORAGE_HOST),
                           ("managed", pyoidn.OIDN_STORAGE_MANAGED)):
        color = pyoidn.Buffer(dev, rgba_bytes, storage=storage)
        output = pyoidn.Buffer(dev, rgb_bytes, storage=storage)
        flt = pyoidn.Filter(dev, pyoidn.OIDN_FILTER_TYPE_RT)
        flt.set_image("color", color, pyoidn.OIDN_FORMAT_FLOAT3, w, h, 0, 16, w * 16)
        flt.set_image("albedo", albedo, pyoidn.OIDN_FORMAT_FLOAT3, w, h)
        flt.set_image("normal", normal, pyoidn.OIDN_FORMAT_FLOAT3, w, h)
        flt.set_image("output", output, pyoidn.OIDN_FORMAT_FLOAT3, w, h)
        flt.set_bool("hdr", True)
        flt.set_bool("cleanAux", True)
        flt.commit()
        if storage == pyoidn.OIDN_STORAGE_DEVICE:
            result = np.empty(w * h * 3, np.float32)
            def frame():
                tex.read_into(pinned)
                color.write(0, rgba_bytes, pinned)
                flt.execute()
                output.read(0, rgb_bytes, result)
                out_tex.write(result)
            row[f"{label}: color write from pinned"] = ms(lambda: color.write(0, rgba_bytes, pinned))
            row[f"{label}: color write from pageable"] = ms(lambda: color.write(0, rgba_bytes, pageable))
        else:
            cview, oview = view(color, rgba_bytes), view(output, rgb_bytes)
            def frame():
                tex.read_into(cview)
                flt.execute()
                out_tex.write(oview)
        row[f"{label}: execute"] = ms(lambda: flt.execute())
        row[f"{label}: whole frame (read-back, filter, upload)"] = ms(lambda: (frame(), ctx.finish()))
        print(dev.get_error())
        flt.release(); color.release(); output.release()
    row["gl upload result (pageable)"] = ms(lambda: (out_tex.write(np.zeros(w * h * 3, np.float32)), ctx.finish()))
    for k, v in row.items():
        print(f"{k:55s} {v if isinstance(v, str) else f'{v:8.3f} ms'}")
    albedo.release(); normal.release(); host.release()
