"""``optim.adapter``: fine-tune a trained network through a few per-channel parameters.

A network for any pattern (``universal``) already knows how to reconstruct; what a new pattern
changes is mostly how strongly each learnt feature should respond. :class:`ChannelAdapter`
gives every convolution of the network a per-output-channel scale and shift (FiLM: Perez et
al., *FiLM: Visual Reasoning with a General Conditioning Layer*, AAAI 2018; the per-pattern
parameters of unified demosaicking networks are of this kind), about 0.3 % of the universal
network's parameters. The network's own weights are frozen (``optim.base_lr_scale = 0``) or
trained at a fraction of the rate.

A scale and a shift after a convolution fold exactly into its weights and bias
(``s * (W x + b) + t = (s W) x + (s b + t)``), so what a run saves for its readers is a plain
network of the same architecture: :func:`folded_state` writes the folded weights under the
checkpoint's ``model/`` keys, and the unfolded ones under ``adapter-base/`` for a resume
(:func:`restore_base`), which is then exact. Nothing outside training knows adapters exist.

Implemented here rather than with ``torch.nn.utils.parametrize``: a forward hook per
convolution leaves the network's ``state_dict`` keys unchanged, so the shipped weights, the
divergence guard's snapshots and every reader of a checkpoint work as they are.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from .config import ADAPTERS

__all__ = ["ADAPTERS", "BASE_PREFIX", "ChannelAdapter", "attach", "folded_state", "restore_base"]

#: Checkpoint section of the unfolded convolution weights of a run with an adapter.
BASE_PREFIX = "adapter-base"


def _key(name: str) -> str:
    return name.replace(".", "-")


class ChannelAdapter(nn.Module):
    """A per-output-channel scale (starting at 1) and shift (starting at 0) after every
    :class:`~torch.nn.Conv2d` of ``network``, applied by forward hooks: a network with its
    adapter attached computes what the folded network (:meth:`folded`) computes.

    Args:
        network: The network to adapt; its convolutions get the hooks.
    """

    def __init__(self, network: nn.Module) -> None:
        super().__init__()
        convs = {n: m for n, m in network.named_modules() if isinstance(m, nn.Conv2d)}
        if not convs:
            raise ValueError("an adapter needs a network with convolutions")
        self.names = list(convs)
        self.scale = nn.ParameterDict(
            {_key(n): nn.Parameter(torch.ones(m.out_channels)) for n, m in convs.items()}
        )
        self.shift = nn.ParameterDict(
            {_key(n): nn.Parameter(torch.zeros(m.out_channels)) for n, m in convs.items()}
        )
        device = next(iter(convs.values())).weight.device
        self.to(device)
        self._hooks = [m.register_forward_hook(self._hook(n)) for n, m in convs.items()]

    def _hook(self, name: str) -> Any:
        def apply(module: nn.Module, inputs: Any, output: torch.Tensor) -> torch.Tensor:
            del module, inputs
            scale = self.scale[_key(name)].to(output.dtype).view(1, -1, 1, 1)
            shift = self.shift[_key(name)].to(output.dtype).view(1, -1, 1, 1)
            return output * scale + shift

        return apply

    def folded(self, network_state: dict[str, torch.Tensor], prefix: str = "") -> dict:
        """``network_state`` (keys under ``prefix``) with each convolution's scale and shift
        folded into its weight and bias."""
        out = dict(network_state)
        for name in self.names:
            scale = self.scale[_key(name)].detach()
            shift = self.shift[_key(name)].detach()
            w, b = f"{prefix}{name}.weight", f"{prefix}{name}.bias"
            weight = out[w]
            out[w] = weight * scale.to(weight.dtype).view(-1, *([1] * (weight.ndim - 1)))
            bias = out.get(b)
            if bias is None:
                raise ValueError(f"{name} has no bias to fold the adapter's shift into")
            out[b] = bias * scale.to(bias.dtype) + shift.to(bias.dtype)
        return out

    def remove(self) -> None:
        """Detach the hooks: the network computes with its own weights again."""
        for hook in self._hooks:
            hook.remove()
        self._hooks = []


def attach(system: nn.Module, form: str) -> ChannelAdapter | None:
    """Give ``system.network`` the adapter ``form`` names (None for ``"none"``), as the
    system's ``adapter`` submodule, so its state travels with the system's."""
    if form == "none":
        return None
    if form != "film":
        raise ValueError(f"unknown adapter {form!r}; expected one of {', '.join(ADAPTERS)}")
    adapter = ChannelAdapter(system.network)
    system.add_module("adapter", adapter)
    return adapter


def folded_state(system: nn.Module) -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
    """``(model, base)``: the system's state with its adapter folded into the network (what
    readers load), and the network's unfolded convolution tensors (what a resume restores)."""
    state = system.state_dict()
    adapter = getattr(system, "adapter", None)
    if not isinstance(adapter, ChannelAdapter):
        return state, {}
    base = {key: state[key] for key in _base_keys(adapter)}
    return adapter.folded(state, prefix="network."), base


def _base_keys(adapter: ChannelAdapter) -> list[str]:
    """The system's state keys of the convolutions ``adapter`` scales."""
    return [f"network.{name}.{kind}" for name in adapter.names for kind in ("weight", "bias")]


def restore_base(system: nn.Module, base: dict[str, torch.Tensor]) -> None:
    """Put the unfolded convolution tensors ``base`` (from :func:`folded_state`) back into the
    network, after the checkpoint's folded ones were loaded."""
    adapter = getattr(system, "adapter", None)
    expected = set(_base_keys(adapter)) if isinstance(adapter, ChannelAdapter) else set()
    if set(base) != expected:
        raise ValueError("the checkpoint's adapter does not match this run's optim.adapter")
    own = system.state_dict()
    with torch.no_grad():
        for key, value in base.items():
            own[key].copy_(value)
