"""SB3 MLP policies as numpy views into one flat float32 vector, and torch's Adam on such a vector.

The suite's policies are small (a few thousand weights), so a torch forward,
backward and optimiser step cost ~1 ms of framework overhead per minibatch for
a few microseconds of arithmetic. The numpy updates (:mod:`~grail_bench.core.ppo_update`,
:mod:`~grail_bench.core.bc_update`) read a policy's weights into one flat
vector, train it in place and copy it back. :class:`StackedMLPs` holds K
copies of one architecture (one per goal) as rows of one ``(K, P)`` array, so
one batched ``matmul`` per layer trains them all; each copy's arithmetic is
the one :class:`FlatMLPs` does on it alone.
"""

from __future__ import annotations

import math
from typing import Any, Iterator, Sequence

import numpy as np
import torch
from torch import nn

#: Activations the numpy networks mirror: (forward, derivative from the activated output).
ACTIVATIONS = {nn.Tanh: (np.tanh, lambda y: 1.0 - y * y), nn.ReLU: (lambda x: np.maximum(x, 0.0), lambda y: y > 0)}


class FlatMLPs:
    """Chains of Linear layers (and extra parameters) as views into one flat float32 vector and its gradient.

    Args:
        chains: Each a sequence of modules applied in order (``Linear`` and the activations in
            :data:`ACTIVATIONS`), e.g. ``[*policy.mlp_extractor.policy_net, policy.action_net]``.
        extra: Parameters used outside the chains (a Gaussian policy's ``log_std``), as views in
            :attr:`extra` and :attr:`extra_grad`.
    """

    def __init__(self, chains: Sequence[Sequence[nn.Module]], extra: Sequence[nn.Parameter] = ()) -> None:
        self.params = [p for chain in chains for m in chain for p in m.parameters()] + list(extra)
        sizes = [p.numel() for p in self.params]
        self.flat = np.zeros(sum(sizes), dtype=np.float32)
        self.grad = np.zeros_like(self.flat)
        views, grads, start = [], [], 0
        for p, n in zip(self.params, sizes):
            # torch's Linear stores (out, in); keep that layout so the flat vector matches the state_dict.
            views.append(self.flat[start:start + n].reshape(p.shape))
            grads.append(self.grad[start:start + n].reshape(p.shape))
            start += n
        pairs = iter(zip(views, grads))
        self.chains = [self._layers(list(chain), pairs) for chain in chains]
        extras = list(pairs)
        self.extra, self.extra_grad = [v for v, _ in extras], [g for _, g in extras]

    @staticmethod
    def mirrors(chain: Sequence[nn.Module]) -> bool:
        """Whether every module of ``chain`` is one :class:`FlatMLPs` can run."""
        return all(isinstance(m, (nn.Linear, *ACTIVATIONS)) for m in chain)

    @staticmethod
    def _layers(modules: list[nn.Module], pairs: Iterator[Any]) -> list[tuple]:
        """``(weight, bias, weight grad, bias grad, activation or None)`` per Linear."""
        layers = []
        for i, module in enumerate(modules):
            if isinstance(module, nn.Linear):
                (w, gw), (b, gb) = next(pairs), next(pairs)
                follower = modules[i + 1] if i + 1 < len(modules) else None
                layers.append((w, b, gw, gb, ACTIVATIONS.get(type(follower))))
        return layers

    @staticmethod
    def forward(layers: list[tuple], x: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """Output and every layer's input."""
        inputs = []
        for w, b, _, _, act in layers:
            inputs.append(x)
            x = x @ w.T + b
            if act is not None:
                x = act[0](x)
        return x, inputs

    @staticmethod
    def backward(layers: list[tuple], inputs: list[np.ndarray], grad_out: np.ndarray) -> None:
        """Write the gradients of ``sum(grad_out * output)`` into the flat gradient."""
        for (w, _, gw, gb, act), x, nxt in zip(reversed(layers), reversed(inputs), reversed(inputs[1:] + [None])):
            if act is not None:  # this layer's activated output is the next layer's input
                grad_out = grad_out * act[1](nxt)
            np.matmul(grad_out.T, x, out=gw)
            np.sum(grad_out, axis=0, out=gb)
            grad_out = grad_out @ w

    def read(self) -> None:
        """Copy the torch parameters into the flat vector (in place: the views stay valid)."""
        _read(self.params, self.flat)

    def write_back(self) -> None:
        """Copy the flat parameters into the torch parameters."""
        _write_back(self.flat, self.params)


def _read(params: Sequence[nn.Parameter], flat: np.ndarray) -> None:
    """Copy ``params`` into ``flat``, one after another (in place: views of ``flat`` stay valid)."""
    flat[:] = np.concatenate([p.detach().numpy().reshape(-1) for p in params])


def _write_back(flat: np.ndarray, params: Sequence[nn.Parameter]) -> None:
    """Copy ``flat`` into ``params``, laid out as :func:`_read` lays them."""
    start = 0
    with torch.no_grad():
        for p in params:
            n = p.numel()
            p.copy_(torch.from_numpy(flat[start:start + n].reshape(p.shape)))
            start += n


class StackedMLPs:
    """K chains of the same shapes (one per policy) as ``(K, ...)`` views into one ``(K, P)`` float32 array.

    Row ``i`` of :attr:`flat` is laid out as :class:`FlatMLPs` lays out copy ``i`` alone, and the batched
    ``matmul`` runs the same BLAS call on each row's slice, so each copy trains bit for bit as it would alone.
    :meth:`forward` and :meth:`backward` take ``k``: only the first ``k`` copies take part (the others keep
    their values and gradients).

    Args:
        chains: One module sequence per copy (as :class:`FlatMLPs`' chains), all of the same shapes.
        extras: Per copy, parameters used outside its chain (a Gaussian policy's ``log_std``), stacked in
            :attr:`extra` and :attr:`extra_grad`.
    """

    def __init__(self, chains: Sequence[Sequence[nn.Module]], extras: Sequence[Sequence[nn.Parameter]] = ()) -> None:
        extras = list(extras) or [[] for _ in chains]
        self.params = [[p for m in chain for p in m.parameters()] + list(extra) for chain, extra in zip(chains, extras)]
        shapes = [tuple(p.shape) for p in self.params[0]]
        if any([tuple(p.shape) for p in params] != shapes for params in self.params):
            raise ValueError("StackedMLPs needs chains of the same shapes")
        copies, sizes = len(chains), [math.prod(shape) for shape in shapes]
        self.flat = np.zeros((copies, sum(sizes)), dtype=np.float32)
        self.grad = np.zeros_like(self.flat)
        pairs, start = [], 0
        for shape, n in zip(shapes, sizes):
            pairs.append((self.flat[:, start:start + n].reshape(copies, *shape),
                          self.grad[:, start:start + n].reshape(copies, *shape)))
            start += n
        assert all(np.shares_memory(v, self.flat) and np.shares_memory(g, self.grad) for v, g in pairs)
        pairs_iter = iter(pairs)
        self.layers = FlatMLPs._layers(list(chains[0]), pairs_iter)
        extra = list(pairs_iter)
        self.extra, self.extra_grad = [v for v, _ in extra], [g for _, g in extra]

    def forward(self, x: np.ndarray, k: int) -> tuple[np.ndarray, list[np.ndarray]]:
        """The first ``k`` copies' outputs on ``x`` (``(k, batch, in)``: a batch per copy) and every layer's input."""
        inputs = []
        for w, b, _, _, act in self.layers:
            inputs.append(x)
            x = np.matmul(x, w[:k].transpose(0, 2, 1)) + b[:k, None, :]
            if act is not None:
                x = act[0](x)
        return x, inputs

    def backward(self, inputs: list[np.ndarray], grad_out: np.ndarray, k: int) -> None:
        """Write the gradients of ``sum(grad_out * output)`` into the first ``k`` rows of :attr:`grad`."""
        layers = self.layers
        for depth in reversed(range(len(layers))):
            w, _, gw, gb, act = layers[depth]
            if act is not None:  # this layer's activated output is the next layer's input
                grad_out = grad_out * act[1](inputs[depth + 1])
            np.matmul(grad_out.transpose(0, 2, 1), inputs[depth], out=gw[:k])
            np.sum(grad_out, axis=1, out=gb[:k])
            if depth:
                grad_out = np.matmul(grad_out, w[:k])

    def read(self) -> None:
        """Copy every copy's torch parameters into its row."""
        for row, params in zip(self.flat, self.params):
            _read(params, row)

    def write_back(self) -> None:
        """Copy every row into its copy's torch parameters."""
        for row, params in zip(self.flat, self.params):
            _write_back(row, params)


class Adam:
    """torch's Adam update rule (bias-corrected, no weight decay or AMSGrad) on one flat vector, or on the rows of
    a ``(K, P)`` array (K vectors stepped together).

    Args:
        size: Length of the parameter vector, or ``(K, P)``.
        betas: torch's ``betas``.
        eps: torch's ``eps``.
    """

    def __init__(self, size: int | tuple[int, int], betas: tuple[float, float] = (0.9, 0.999),
                 eps: float = 1e-8) -> None:
        self.m, self.v = np.zeros(size, dtype=np.float32), np.zeros(size, dtype=np.float32)
        self.beta1, self.beta2 = betas
        self.eps = eps
        self.steps = 0

    def step(self, params: np.ndarray, grad: np.ndarray, lr: float, rows: int | None = None) -> None:
        """One step of ``params`` (in place) along ``grad`` at learning rate ``lr``.

        With ``rows``, only the first ``rows`` vectors of a ``(K, P)`` state step (``params`` and ``grad`` are
        those rows); the step count is shared, so a row that stops stepping stays stopped.
        """
        m, v, beta1, beta2 = self.m[:rows], self.v[:rows], self.beta1, self.beta2
        self.steps += 1
        m *= beta1
        m += (1 - beta1) * grad
        v *= beta2
        v += (1 - beta2) * grad * grad
        correction1, correction2 = 1 - beta1 ** self.steps, 1 - beta2 ** self.steps
        params -= (lr / correction1) * m / (np.sqrt(v) / np.sqrt(correction2) + self.eps)
