"""Clearing and copying RGBA32F images (app/rendering/image_ops.py, glsl/image_copy.comp) both
ways, the compute passes (a GPU's) and the framebuffer clear and blit (a software rasteriser's),
on llvmpipe: every texel, sizes that are not whole work groups, the device's choice, and the
refusals."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.gl.context import is_software
from radiance_probes.rendering.image_ops import clear_image, copy_image, uses_compute


def _texture(ctx, image: np.ndarray):
    h, w, c = image.shape
    return ctx.texture((w, h), c, np.ascontiguousarray(image, np.float32).tobytes(), dtype="f4")


def _read(texture) -> np.ndarray:
    w, h = texture.size
    return np.frombuffer(texture.read(), np.float32).reshape(h, w, texture.components)


@pytest.mark.parametrize("compute", [True, False])
@pytest.mark.parametrize("size", [(37, 21), (16, 16), (1, 1)])
def test_clear_zeroes_every_texel(ctx, compute, size):
    w, h = size
    texture = _texture(ctx, np.random.default_rng(w).random((h, w, 4), np.float32) + 1.0)
    clear_image(texture, compute=compute)
    assert not np.any(_read(texture))
    texture.release()


@pytest.mark.parametrize("compute", [True, False])
@pytest.mark.parametrize("size", [(37, 21), (16, 16), (1, 1)])
def test_copy_is_texel_for_texel(ctx, compute, size):
    w, h = size
    rng = np.random.default_rng(w * h)
    image = rng.normal(0.0, 1e3, (h, w, 4)).astype(np.float32)
    image[0, 0] = [1e-38, -0.0, 3.4e38, 7.0]   # float32 kept whole: no 8-bit path, no filtering
    source, target = _texture(ctx, image), _texture(ctx, np.zeros_like(image))
    copy_image(source, target, compute=compute)
    np.testing.assert_array_equal(_read(target), image)
    np.testing.assert_array_equal(_read(source), image)
    source.release()
    target.release()


def test_the_device_chooses(ctx):
    assert uses_compute(ctx) == (not is_software(ctx))
    texture = _texture(ctx, np.ones((5, 7, 4), np.float32))
    clear_image(texture)
    assert not np.any(_read(texture))
    texture.release()


def test_refusals(ctx):
    a = ctx.texture((8, 8), 4, dtype="f4")
    rgb = ctx.texture((8, 8), 3, dtype="f4")
    small = ctx.texture((4, 8), 4, dtype="f4")
    bytes4 = ctx.texture((8, 8), 4)
    with pytest.raises(ValueError, match="differ in size"):
        copy_image(a, small)
    with pytest.raises(ValueError, match="RGBA32F texture expected, got 3 components"):
        copy_image(rgb, a)
    with pytest.raises(ValueError, match="of f1"):
        clear_image(bytes4)
    for t in (a, rgb, small, bytes4):
        t.release()
