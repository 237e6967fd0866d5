"""AnalyticMLP: closed-form input derivatives against autograd and finite differences."""

from __future__ import annotations

import pytest
import torch
from torch.func import functional_call, hessian, jacrev, vmap

from id_learning.models.nets import AnalyticMLP

ACTIVATIONS = ('tanh', 'softplus')
DEPTHS = (1, 2, 3)


@pytest.fixture(autouse=True, scope='module')
def one_thread():
    """These networks are small: one thread is fastest, more only contend on a busy machine."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


def make_net(n_in: int, n_out: int, activation: str, depth: int, seed: int = 0) -> AnalyticMLP:
    generator = torch.Generator().manual_seed(seed)
    return AnalyticMLP(n_in, n_out, 16, depth, activation, generator=generator).double()


def random_inputs(shape: tuple[int, ...], seed: int) -> torch.Tensor:
    return torch.randn(shape, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)


def scalar_function(net: AnalyticMLP):
    return lambda x: net(x.unsqueeze(0))[0, 0]


@pytest.mark.parametrize('depth', DEPTHS)
@pytest.mark.parametrize('activation', ACTIVATIONS)
def test_jacobian_matches_autograd(activation: str, depth: int) -> None:
    net = make_net(5, 4, activation, depth)
    x = random_inputs((9, 5), seed=1)
    values, jacobian = net.jacobian(x)
    reference = vmap(jacrev(lambda row: net(row.unsqueeze(0))[0]))(x)
    assert jacobian.shape == (9, 4, 5)
    assert reference.abs().max() > 1e-2  # not a vacuous comparison of zeros
    torch.testing.assert_close(values, net(x), rtol=0, atol=1e-12)
    torch.testing.assert_close(jacobian, reference, rtol=0, atol=1e-10)


@pytest.mark.parametrize('depth', DEPTHS)
@pytest.mark.parametrize('activation', ACTIVATIONS)
def test_gradient_and_hessian_vector_product_match_autograd(activation: str, depth: int) -> None:
    net = make_net(6, 1, activation, depth, seed=2)
    x, u = random_inputs((8, 6), seed=3), random_inputs((8, 6), seed=4)
    value, gradient, hvp = net.gradient_and_hvp(x, u)
    f = scalar_function(net)
    reference_hessian = vmap(hessian(f))(x)
    reference_hvp = torch.einsum('bij,bj->bi', reference_hessian, u)
    assert reference_hvp.abs().max() > 1e-2
    torch.testing.assert_close(value, net(x)[:, 0], rtol=0, atol=1e-12)
    torch.testing.assert_close(gradient, vmap(jacrev(f))(x), rtol=0, atol=1e-10)
    torch.testing.assert_close(hvp, reference_hvp, rtol=0, atol=1e-10)
    plain_value, plain_gradient = net.gradient(x)
    torch.testing.assert_close(plain_value, value, rtol=0, atol=0)
    torch.testing.assert_close(plain_gradient, gradient, rtol=0, atol=1e-14)


@pytest.mark.parametrize('activation', ACTIVATIONS)
def test_derivatives_match_central_finite_differences(activation: str) -> None:
    net = make_net(4, 3, activation, 2, seed=5)
    scalar = make_net(4, 1, activation, 2, seed=6)
    x, u = random_inputs((5, 4), seed=7), random_inputs((5, 4), seed=8)
    step = 1e-5
    _, jacobian = net.jacobian(x)
    _, gradient, hvp = scalar.gradient_and_hvp(x, u)
    for k in range(4):
        shift = torch.zeros(4, dtype=torch.float64)
        shift[k] = step
        column = (net(x + shift) - net(x - shift)) / (2 * step)
        torch.testing.assert_close(jacobian[:, :, k], column, rtol=0, atol=1e-8)
        partial = (scalar(x + shift) - scalar(x - shift))[:, 0] / (2 * step)
        torch.testing.assert_close(gradient[:, k], partial, rtol=0, atol=1e-8)
    # H u is the directional derivative of the gradient along u.
    _, gradient_plus = scalar.gradient(x + step * u)
    _, gradient_minus = scalar.gradient(x - step * u)
    torch.testing.assert_close(
        hvp, (gradient_plus - gradient_minus) / (2 * step), rtol=0, atol=1e-8
    )


def test_hessian_vector_product_is_differentiable_with_respect_to_the_weights() -> None:
    # Training differentiates the analytic derivatives w.r.t. the weights: compare that
    # gradient with autograd through torch.func's Hessian of the same parameters.
    net = make_net(4, 1, 'softplus', 2, seed=9)
    x, u = random_inputs((6, 4), seed=10), random_inputs((6, 4), seed=11)
    params = dict(net.named_parameters())
    # The output bias shifts f but none of its derivatives: it is not in the loss's graph.
    weights = [value for name, value in params.items() if name != 'layers.2.bias']

    def analytic_loss(p: dict[str, torch.Tensor]) -> torch.Tensor:
        _, gradient, hvp = functional_call(net, p, (x, u), strict=True)
        return (gradient**2).sum() + (hvp**2).sum()

    def reference_loss(p: dict[str, torch.Tensor]) -> torch.Tensor:
        def f(row: torch.Tensor) -> torch.Tensor:
            return functional_call(net, p, (row.unsqueeze(0),))[0, 0]

        gradient = vmap(jacrev(f))(x)
        hvp = torch.einsum('bij,bj->bi', vmap(hessian(f))(x), u)
        return (gradient**2).sum() + (hvp**2).sum()

    # functional_call runs forward(); route it to gradient_and_hvp for the analytic loss.
    net.forward = net.gradient_and_hvp  # type: ignore[method-assign]
    analytic = torch.autograd.grad(analytic_loss(params), weights)
    del net.forward
    reference = torch.autograd.grad(reference_loss(params), weights)
    for mine, theirs in zip(analytic, reference, strict=True):
        torch.testing.assert_close(mine, theirs, rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize('batch', [1, 33])
def test_derivatives_have_the_documented_shapes_for_any_batch(batch: int) -> None:
    net = make_net(3, 2, 'tanh', 2)
    scalar = make_net(3, 1, 'tanh', 2)
    x = random_inputs((batch, 3), seed=12)
    values, jacobian = net.jacobian(x)
    f, gradient, hvp = scalar.gradient_and_hvp(x, x)
    assert values.shape == (batch, 2)
    assert jacobian.shape == (batch, 2, 3)
    assert f.shape == (batch,)
    assert gradient.shape == hvp.shape == (batch, 3)


def test_initial_weights_come_from_the_generator_and_leave_the_global_rng_alone() -> None:
    before = torch.random.get_rng_state()
    first = make_net(3, 2, 'tanh', 2, seed=13)
    second = make_net(3, 2, 'tanh', 2, seed=13)
    other = make_net(3, 2, 'tanh', 2, seed=14)
    assert torch.equal(torch.random.get_rng_state(), before)
    for name, value in first.state_dict().items():
        assert torch.equal(value, second.state_dict()[name])
    assert not torch.equal(first.layers[0].weight, other.layers[0].weight)
    assert sorted(first.state_dict()) == [
        f'layers.{i}.{kind}' for i in range(3) for kind in ('bias', 'weight')
    ]


def test_gradient_of_a_vector_output_net_is_refused() -> None:
    net = make_net(3, 2, 'tanh', 1)
    x = random_inputs((2, 3), seed=15)
    with pytest.raises(ValueError, match='scalar-output'):
        net.gradient_and_hvp(x, x)
    with pytest.raises(ValueError, match='scalar-output'):
        net.gradient(x)


def test_activation_without_a_second_derivative_is_refused() -> None:
    with pytest.raises(ValueError, match=r"'relu'.*softplus"):
        AnalyticMLP(3, 1, activation='relu')


def test_fan_in_initialisation_draws_a_truncated_normal_of_std_one_over_sqrt_fan_in() -> None:
    net = AnalyticMLP(400, 300, width=500, depth=1, init='fan_in', output_gain=0.5,
                      generator=torch.Generator().manual_seed(3))  # fmt: skip
    first, last = net.linears()
    std = 1.0 / 400**0.5
    # A normal truncated at two std keeps 0.88 of its variance: std 0.8796 sigma.
    assert float(first.weight.std()) == pytest.approx(0.8796 * std, rel=0.02)
    assert float(first.weight.abs().max()) <= 2 * std
    # The output layer: fan-in 500, scaled by the output gain.
    assert float(last.weight.std()) == pytest.approx(0.5 * 0.8796 / 500**0.5, rel=0.02)
    assert torch.count_nonzero(first.bias) == 0
    xavier = AnalyticMLP(400, 300, width=500, depth=1, generator=torch.Generator().manual_seed(3))
    bound = (6.0 / (400 + 500)) ** 0.5
    assert float(xavier.linears()[0].weight.std()) == pytest.approx(bound / 3**0.5, rel=0.02)
    with pytest.raises(ValueError, match='init must be one of'):
        AnalyticMLP(2, 1, init='orthogonal')
