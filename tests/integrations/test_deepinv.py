"""splitcam.integrations.deepinv: the splitter sensor as a deepinv physics operator.

deepinv's own checks (adjointness, operator norm) on every library pattern, splitcam's noise
models behind deepinv's interface, learnable kernels, odd image sizes, a deepinv solver on the
operator and through splitcam's evaluation protocol. Skipped where deepinv is not installed
(``pip install 'splitcam[deepinv]'``).
"""

from __future__ import annotations

import pytest
import torch

# splitcam's module first: where deepinv is missing, or the installed torchvision cannot load
# beside this torch, the skip says why in one line (and how to install the matching one).
pytest.importorskip("splitcam.integrations.deepinv", exc_type=ImportError)
dinv = pytest.importorskip("deepinv")

from splitcam import patterns  # noqa: E402
from splitcam.evaluation.protocol import score, simulate_and_reconstruct  # noqa: E402
from splitcam.integrations.deepinv import (  # noqa: E402
    DeepinvReconstructor,
    SplitcamGaussianNoise,
    SplitcamPhotonNoise,
    SplitterPhysics,
    noise_model,
)
from splitcam.physics.noise import Exposure, GaussianNoise  # noqa: E402
from splitcam.physics.sensor import LearnableSplitterSensor, SplitterSensor  # noqa: E402
from splitcam.physics.system import simulate  # noqa: E402

ODD_SIZES = [(1, 1), (5, 7), (13, 17), (31, 9)]


@pytest.mark.parametrize("name", patterns.names())
def test_deepinv_adjointness_test_on_every_library_pattern(name):
    torch.manual_seed(0)
    physics = SplitterPhysics(name)
    x = torch.rand(1, 3, 19, 23, dtype=torch.float64)
    error = physics.adjointness_test(x, num_samples=4)
    assert float(error) < 1e-12


def test_deepinv_adjointness_test_on_pattern_files_a_user_wrote(tmp_path):
    """Patterns read from files (random valid ones, periods up to 4x4 and kernels up to 5x5)
    pass deepinv's own adjointness test on an image that ends part-way through a period."""
    import numpy as np

    from splitcam.patterns.files import save
    from splitcam.patterns.random import random_pattern

    rng = np.random.default_rng(7)
    for i in range(4):
        path = save(random_pattern(rng, name=f"mine{i}"), tmp_path / f"mine{i}.toml")
        physics = SplitterPhysics(str(path))
        x = torch.rand(1, 3, 17, 22, dtype=torch.float64)
        assert float(physics.adjointness_test(x, num_samples=4)) < 1e-12


@pytest.mark.parametrize("name", ["A", "C", "router-best"])
def test_adjointness_at_odd_sizes(name):
    torch.manual_seed(1)
    physics = SplitterPhysics(name)
    for size in ODD_SIZES:
        x = torch.rand(2, 3, *size, dtype=torch.float64)
        assert float(physics.adjointness_test(x)) < 1e-12, size


def _power_iteration(sensor: SplitterSensor, shape, iters: int) -> float:
    """||A||_2 by power iteration on A^T A with splitcam's forward and adjoint (no deepinv)."""
    gen = torch.Generator().manual_seed(7)
    x = torch.randn(shape, generator=gen, dtype=torch.float64)
    for _ in range(iters):
        x = sensor.adjoint(sensor(x))
        x = x / x.norm()
    return float(sensor(x).norm())


def _dense_norm(sensor: SplitterSensor, shape) -> float:
    """||A||_2 from the dense matrix of A (columns: A applied to each unit image)."""
    n = int(torch.tensor(shape).prod())
    basis = torch.eye(n, dtype=torch.float64).reshape(n, *shape[1:])
    return float(torch.linalg.matrix_norm(sensor(basis).reshape(n, -1).T, ord=2))


@pytest.mark.parametrize("name", ["A", "D", "bayer", "router-zou"])
def test_compute_norm_matches_an_independent_power_iteration(name):
    torch.manual_seed(2)
    physics = SplitterPhysics(name)
    shape = (1, 3, 12, 14)
    x0 = torch.zeros(shape, dtype=torch.float64)
    norm = float(physics.compute_norm(x0, max_iter=2000, tol=1e-12, squared=False, verbose=False))
    sqnorm = float(physics.compute_sqnorm(x0, max_iter=2000, tol=1e-12, verbose=False))
    ours = _power_iteration(physics.splitter, shape, iters=2000)
    exact = _dense_norm(physics.splitter, shape)
    assert ours == pytest.approx(exact, rel=1e-6)
    assert norm == pytest.approx(ours, rel=1e-4)
    assert sqnorm == pytest.approx(ours**2, rel=1e-4)


@pytest.mark.parametrize("name", ["A", "E", "quad"])
def test_operator_is_splitcams_sensor_at_odd_sizes(name):
    sensor = SplitterSensor(name)
    physics = SplitterPhysics(name)
    for size in ODD_SIZES:
        x = torch.rand(2, 3, *size, dtype=torch.float64)
        y = torch.rand(2, 1, *size, dtype=torch.float64)
        assert physics.A(x).shape == (2, 1, *size)
        assert physics.A_adjoint(y).shape == (2, 3, *size)
        assert torch.equal(physics.A(x), sensor(x))
        assert torch.equal(physics.A_adjoint(y), sensor.adjoint(y))
        assert torch.equal(physics(x), sensor(x))  # no noise by default


def test_a_given_sensor_is_used_as_it_is():
    sensor = SplitterSensor("B")
    physics = SplitterPhysics(sensor)
    assert physics.splitter is sensor
    assert physics.pattern.name == "B"
    with pytest.raises(ValueError, match=r"\(N, 3, H, W\)"):
        physics.A(torch.rand(3, 8, 8))


def test_float32_inputs_give_float32_measurements():
    physics = SplitterPhysics("D")
    x = torch.rand(1, 3, 9, 11)
    assert physics.A(x).dtype == torch.float32
    assert physics.A_adjoint(physics.A(x)).dtype == torch.float32


# --- noise ---------------------------------------------------------------------------------


def test_gaussian_wrapper_std_matches_sigma_over_255():
    physics = SplitterPhysics("D", noise=15.0, seed=3)
    x = torch.rand(2, 3, 160, 160, dtype=torch.float64)
    residual = physics(x) - physics.A(x)
    assert residual.std().item() == pytest.approx(15 / 255, rel=0.02)
    assert abs(residual.mean().item()) < 3 * (15 / 255) / residual.numel() ** 0.5
    assert physics.noise_model.sigma_8bit == 15.0
    assert float(physics.noise_model.sigma) == pytest.approx(15 / 255)


def test_gaussian_wrapper_draws_splitcams_noise():
    z = torch.rand(2, 1, 20, 30, dtype=torch.float64)
    ours, _ = GaussianNoise(10.0, seed=5)(z)
    assert torch.equal(SplitcamGaussianNoise(10.0, seed=5)(z), ours)
    model = SplitcamGaussianNoise(10.0, seed=0)
    assert torch.equal(model(z, seed=5), ours)  # deepinv's seed argument reseeds
    model.reset_rng()
    assert torch.equal(model(z), SplitcamGaussianNoise(10.0, seed=0)(z))
    assert torch.equal(SplitcamGaussianNoise(0.0)(z), z)


def test_gaussian_wrapper_level_in_deepinv_and_8bit_units():
    model = SplitcamGaussianNoise(5.0)
    model.update_parameters(sigma=20 / 255)
    assert model.sigma_8bit == pytest.approx(20.0)
    model.update_parameters(sigma_8bit=7.0)
    assert model.sigma_8bit == 7.0
    z = torch.zeros(1, 1, 200, 200)
    assert model(z, sigma=torch.tensor(30 / 255)).std().item() == pytest.approx(30 / 255, rel=0.02)
    with pytest.raises(ValueError, match="one noise level"):
        model.update_parameters(sigma=torch.tensor([0.1, 0.2]))
    with pytest.raises(ValueError):
        SplitcamGaussianNoise(-1.0)


def test_gaussian_noise_keeps_gradients():
    x = torch.rand(1, 3, 8, 8, dtype=torch.float64, requires_grad=True)
    SplitterPhysics("A", noise=10.0)(x).sum().backward()
    assert x.grad is not None and torch.isfinite(x.grad).all()


def test_photon_wrapper_agrees_with_splitcam_for_the_same_seed():
    exposure = Exposure(200.0, read_noise=3.0, gain=0.5, bits=10)
    physics = SplitterPhysics("A", noise=exposure, seed=11)
    x = torch.rand(2, 3, 16, 18, dtype=torch.float64)
    clean = physics.A(x)
    expected = exposure.apply(clean, torch.Generator().manual_seed(11))
    assert torch.equal(physics(x), expected)
    assert isinstance(physics.noise_model, SplitcamPhotonNoise)
    by_number = SplitcamPhotonNoise(200.0, seed=11, read_noise=3.0, gain=0.5, bits=10)
    assert torch.equal(by_number(clean), expected)


def test_photon_wrapper_statistics():
    exposure = Exposure(300.0, read_noise=4.0)
    model = SplitcamPhotonNoise(exposure, seed=0)
    z = torch.full((1, 1, 300, 300), 1.5, dtype=torch.float64)
    y = model(z)
    a, b = exposure.variance_coefficients()
    assert y.mean().item() == pytest.approx(1.5, rel=0.01)
    assert y.var().item() == pytest.approx(a * 1.5 + b, rel=0.03)
    assert float(model.gain) == pytest.approx(a)
    assert float(model.sigma) ** 2 == pytest.approx(b)
    with pytest.raises(ValueError, match="in the Exposure"):
        SplitcamPhotonNoise(exposure, read_noise=1.0)


def test_noise_model_of_each_level():
    assert isinstance(noise_model(None), dinv.physics.ZeroNoise)
    assert isinstance(noise_model(3), SplitcamGaussianNoise)
    assert isinstance(noise_model(Exposure(100.0)), SplitcamPhotonNoise)
    theirs = dinv.physics.PoissonNoise(gain=0.1)
    assert noise_model(theirs) is theirs
    physics = SplitterPhysics("D")
    physics.set_noise_model(12.0)
    assert physics.noise_model.sigma_8bit == 12.0
    with pytest.raises(TypeError):
        noise_model("loud")
    with pytest.raises(ValueError):
        noise_model(float("nan"))


# --- learnable kernels ---------------------------------------------------------------------


def test_learnable_kernels_are_parameters_and_receive_gradients_through_a():
    sensor = LearnableSplitterSensor("D", init="random", generator=torch.Generator().manual_seed(0))
    physics = SplitterPhysics(sensor, noise=5.0)
    names = [n for n, _ in physics.named_parameters()]
    assert names == ["splitter.logits"]
    x = torch.rand(2, 3, 11, 13)
    target = torch.rand(2, 1, 11, 13)
    (physics.A(x) - target).square().mean().backward()
    grad = sensor.logits.grad
    assert grad is not None and torch.isfinite(grad).all() and grad.abs().sum() > 0
    # one step of a deepinv-style optimiser changes the operator
    before = physics.A(x).detach()
    torch.optim.SGD(physics.parameters(), lr=10.0).step()
    assert not torch.allclose(physics.A(x), before)
    assert physics.pattern.provenance == "learned"


def test_learnable_adjoint_stays_exact():
    sensor = LearnableSplitterSensor("A", init="random", generator=torch.Generator().manual_seed(1))
    physics = SplitterPhysics(sensor).double()
    x = torch.rand(1, 3, 15, 9, dtype=torch.float64)
    with torch.no_grad():
        assert float(physics.adjointness_test(x)) < 1e-12


# --- solvers ---------------------------------------------------------------------------------


def _smooth_scene(h: int, w: int) -> torch.Tensor:
    yy, xx = torch.meshgrid(torch.linspace(0, 1, h), torch.linspace(0, 1, w), indexing="ij")
    return torch.stack([0.2 + 0.6 * xx, 0.3 + 0.4 * yy, 0.8 - 0.5 * xx * yy])[None]


def test_a_tv_proximal_gradient_solver_runs_and_fits_the_data():
    torch.manual_seed(0)
    physics = SplitterPhysics("D")
    x = _smooth_scene(21, 27)
    y = physics(x)
    stepsize = 1.0 / float(physics.compute_sqnorm(torch.zeros_like(x), verbose=False))
    solver = dinv.optim.PGD(
        data_fidelity=dinv.optim.L2(),
        prior=dinv.optim.TVPrior(n_it_max=20),
        lambda_reg=1e-3,
        stepsize=stepsize,
        max_iter=60,
    )
    with torch.no_grad():
        estimate = solver(y, physics)
    first = physics.A_adjoint(y)
    assert estimate.shape == x.shape
    assert (physics.A(estimate) - y).norm() < 0.1 * (physics.A(first) - y).norm()
    assert (estimate - x).square().mean() < (first - x).square().mean()


def test_a_deepinv_solver_through_the_evaluation_protocol():
    physics = SplitterPhysics("D")
    seen = []

    def pseudo_inverse(y, physics):
        seen.append((y, physics.noise_model.sigma_8bit))
        return physics.A_dagger(y)

    method = DeepinvReconstructor(pseudo_inverse, physics, name="lsqr")
    assert method.pattern.name == "D" and method.name == "lsqr"
    rgb = _smooth_scene(16, 16)[0]
    for sigma in (0.0, 10.0):
        estimate = simulate_and_reconstruct(method, physics.splitter, "scene", rgb, sigma)
        y, level = seen[-1]
        assert level == sigma and estimate.shape == rgb.shape
        # the solver saw the protocol's raw image (same scene, same evaluation noise)
        assert torch.equal(y, simulate(physics.splitter, rgb[None], "scene", sigma))
        assert 0 <= estimate.min() and estimate.max() <= 1
        assert score(estimate, rgb)["psnr"] > 10


def test_any_splitcam_noise_model_becomes_a_deepinv_noise_model():
    """A noise model defined outside the library (uniform noise) reaches deepinv through the
    NoiseModel interface: its draws and its variance, with nothing else to register."""
    from dataclasses import dataclass

    from splitcam.integrations.deepinv import SplitcamNoise
    from splitcam.physics.noise import NoiseModel

    @dataclass(frozen=True)
    class Uniform(NoiseModel):
        width: float

        def apply(self, raw, generator):
            u = torch.rand(tuple(raw.shape), generator=generator, dtype=torch.float64)
            return raw + ((2 * u - 1) * self.width / 255).to(raw.dtype)

        def variance_coefficients(self):
            return 0.0, (self.width / 255) ** 2 / 3

        def label(self):
            return f"U{self.width:g}"

    model = noise_model(Uniform(30.0), seed=4)
    assert isinstance(model, SplitcamNoise)
    assert float(model.sigma) == pytest.approx(30.0 / 255 / 3**0.5)
    z = torch.full((1, 1, 64, 64), 0.5, dtype=torch.float64)
    y = model(z)
    assert float((y - z).abs().max()) <= 30.0 / 255 + 1e-12
    assert float((y - z).std()) == pytest.approx(float(model.sigma), rel=0.1)
    model.reset_rng()
    assert torch.equal(model(z), y)
