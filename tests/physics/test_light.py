"""The sRGB transfer pair and light domains (splitcam.physics.light)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from splitcam.physics import DOMAINS, check_domain, linear_to_srgb, srgb_to_linear


def _decode_np(u: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1, written out in numpy."""
    return np.where(u <= 0.04045, u / 12.92, ((u + 0.055) / 1.055) ** 2.4)


def _encode_np(lin: np.ndarray) -> np.ndarray:
    lin = np.clip(lin, 0.0, None)
    return np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)


def test_decoding_at_the_breakpoint_follows_the_formula() -> None:
    u = torch.tensor([0.0, 0.04045, 0.5, 1.0], dtype=torch.float64)
    lin = srgb_to_linear(u)
    assert lin[0] == 0 and lin[-1] == pytest.approx(1.0, abs=1e-15)
    assert lin[1] == 0.04045 / 12.92  # the straight segment up to and including the break
    assert lin[2] == pytest.approx(((0.5 + 0.055) / 1.055) ** 2.4, rel=1e-15)
    above = srgb_to_linear(torch.tensor([0.04045 + 1e-12], dtype=torch.float64))
    assert float(above) == pytest.approx(((0.04045 + 1e-12 + 0.055) / 1.055) ** 2.4, rel=1e-14)
    assert abs(float(above) - 0.04045 / 12.92) < 1e-8  # continuous at the break
    enc = linear_to_srgb(torch.tensor([0.0031308, 0.0031308 + 1e-12], dtype=torch.float64))
    assert float(enc[0]) == pytest.approx(12.92 * 0.0031308, rel=1e-15)
    assert abs(float(enc[1] - enc[0])) < 1e-7


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_transfer_pair_matches_a_numpy_reference_in_any_shape(dtype) -> None:
    gen = torch.Generator().manual_seed(0)
    u = torch.rand(2, 3, 5, 7, generator=gen, dtype=torch.float64).to(dtype)
    tol = {"rtol": 1e-6, "atol": 1e-7} if dtype == torch.float32 else {"rtol": 1e-13, "atol": 0}
    lin = srgb_to_linear(u)
    assert lin.dtype == dtype and lin.shape == u.shape
    np.testing.assert_allclose(lin.numpy(), _decode_np(u.double().numpy()), **tol)
    enc = linear_to_srgb(lin)
    np.testing.assert_allclose(enc.numpy(), _encode_np(lin.double().numpy()), **tol)
    for shape in [(), (4,), (1, 1, 1, 2, 3)]:
        x = torch.full(shape, 0.3, dtype=dtype)
        assert srgb_to_linear(x).shape == shape and linear_to_srgb(x).shape == shape


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_every_8bit_value_round_trips_exactly(dtype) -> None:
    v = torch.arange(256, dtype=dtype)
    back = linear_to_srgb(srgb_to_linear(v / 255)).clamp(0, 1) * 255
    assert torch.equal(back.round(), v)


def test_transfer_pair_is_differentiable_outside_zero_to_one() -> None:
    x = torch.tensor([-0.2, 0.0, 0.002, 0.03, 0.5, 1.3], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(srgb_to_linear, (x,))
    assert torch.autograd.gradcheck(linear_to_srgb, (x,))
    out = linear_to_srgb(torch.tensor([-1.0, 2.0])).tolist()
    assert out[0] == pytest.approx(-12.92) and out[1] > 1  # not clipped, never NaN
    with pytest.raises(TypeError, match="floating"):
        srgb_to_linear(torch.arange(3))


def test_check_domain() -> None:
    assert DOMAINS == ("srgb", "linear")
    assert check_domain(" Linear ") == "linear"
    with pytest.raises(ValueError, match="srgb, linear"):
        check_domain("gamma")
