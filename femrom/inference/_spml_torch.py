r"""The torch side of SpML: the parametrisation, the loss and the export to numpy terms.

Imported only when :class:`~femrom.inference.SpML` fits (torch is the optional
``ml`` extra). Everything is float64 on the CPU; the initial weights come from
a seeded ``torch.Generator`` (no global random state), so a seed gives the
same weights bit for bit.

Training coordinates are scaled, ``x = q^ / s_q`` and ``w = q^' / s_v`` (the
root mean square of each coordinate), and the scalar functions carry the
energy scales ``c_U = f s_q``, ``c_F = f s_v`` (``f``: the RMS of the step-1
target); :meth:`SpMLModule.export` folds the scales into the first layers
and coefficients, so the numpy terms take ``q^`` and ``q^'`` as they are.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import torch

from femrom._errors import FemromValueError
from femrom.inference._networks import (ConvexPowers, NetworkLayer, ScalarNetwork, SymmetricPolynomial, derivative_map,
                                       monomials, multi_indices)

DTYPE = torch.float64

#: The raw output weight of a switched-off dissipation network (:func:`prune`), and the export's
#: threshold below which the network is left out (``softplus(-35) = 6e-16`` of the force scale).
PRUNED_RAW, PRUNED = -40.0, -35.0


def _tensor(x) -> torch.Tensor:
    return torch.as_tensor(np.asarray(x, dtype=float), dtype=DTYPE)


class SpMLModule(torch.nn.Module):
    """Mass ``L L^T``, potential ``U^`` and dissipation ``F^`` of SpML in scaled coordinates.

    Parameters
    ----------
    r : int
    config : SpMLConfig
    scales : dict
        ``q`` (r,), ``v`` (r,) coordinate scales, ``potential``, ``dissipation`` energy scales.
    mass0 : (r, r) ndarray
        The step-1 mass (the identity for a mass-orthonormal basis): ``L`` starts at its Cholesky factor.
    generator : torch.Generator
    initial : dict, optional
        ``{"alpha": {degree: (n,) ndarray}}``: the monomials' starting coefficients (scaled units).
    hysteresis : dict, optional
        The learned sliders (:class:`~femrom.inference.LearnedHysteresis`): ``direction`` (r,),
        ``thresholds`` (p,), starting ``weights`` (p,) and ``top`` (the top slider of the monotone
        shape, or ``None``): :meth:`_hysteresis_terms`.
    """

    def __init__(self, r: int, config, scales: dict, mass0: np.ndarray, linear: list, generator: torch.Generator,
                 initial: dict | None = None, hysteresis: dict | None = None):
        super().__init__()
        self.r, self.config = r, config
        self._linear_terms(linear)
        self._hysteresis_terms(hysteresis, scales)
        self.register_buffer("sq", _tensor(scales["q"]))
        self.register_buffer("sv", _tensor(scales["v"]))
        self.cU, self.cF = float(scales["potential"]), float(scales["dissipation"])
        self.register_buffer("L0", _tensor(np.linalg.cholesky(mass0)))

        def normal(*shape, std):
            return torch.nn.Parameter(std * torch.randn(*shape, generator=generator, dtype=DTYPE))

        def zeros(*shape):
            return torch.nn.Parameter(torch.zeros(*shape, dtype=DTYPE))

        if config.learn_mass:
            self.mass_lower, self.mass_log_diagonal = zeros(r, r), zeros(r)
        # potential: monomials of degree 3 and 4 (index lists) and an MLP; both start at zero force
        self.indices = {d: torch.as_tensor(multi_indices(r, d)) for d in config.potential_degrees}
        self._maps = {}
        alpha0 = initial.get("alpha", {}) if initial else {}
        self.alpha = torch.nn.ParameterDict({str(d): torch.nn.Parameter(_tensor(alpha0[d])) if d in alpha0
                                             else zeros(len(i)) for d, i in self.indices.items()})
        widths = (r, *config.potential_widths)
        self.u_weights = torch.nn.ParameterList(
            [normal(b, a, std=1.0 / np.sqrt(a)) for a, b in zip(widths[:-1], widths[1:])])
        self.u_biases = torch.nn.ParameterList([normal(b, std=0.1) for b in widths[1:]])
        self.u_output = zeros(widths[-1]) if config.potential_widths else None
        # dissipation: convex powers and an input-convex network, started small
        self.dissipative = config.learn_dissipation
        n_dir = r if config.dissipation_directions is None else int(config.dissipation_directions)
        if self.dissipative and n_dir:
            self.d_cubic, self.d_quartic = normal(n_dir, r, std=0.1), normal(n_dir, r, std=0.1)
        else:
            self.d_cubic = self.d_quartic = None
        dwidths = tuple(config.dissipation_widths) if self.dissipative else ()
        self.f_input = torch.nn.ParameterList([normal(w, r, std=1.0 / np.sqrt(r)) for w in dwidths])
        self.f_biases = torch.nn.ParameterList([normal(w, std=0.1) for w in dwidths])
        self.f_hidden_raw = torch.nn.ParameterList(
            [normal(b, a, std=1.0 / np.sqrt(a)) for a, b in zip(dwidths[:-1], dwidths[1:])])
        self.f_output_raw = torch.nn.Parameter(torch.full((dwidths[-1],), -6.0, dtype=DTYPE)) if dwidths else None

    # -- the pieces ---------------------------------------------------------------------
    def _linear_terms(self, linear: list) -> None:
        """Step 1's learned linear terms, refined in their structure (``refine_linear``) or fixed.

        ``"spd"``: ``X = G G^T + eps I`` with ``G = G_1 (I + P)``; ``"psd"``: ``X = G G^T`` with
        ``G = G_1 + c P``; ``"free"``: ``X = X_1 + c P``; ``G_1`` the symmetric square root of
        step 1's ``X_1 - eps I``, ``c`` its scale, ``P`` trained from 0 (so training starts at step 1).
        """
        self.linear = []
        for i, term in enumerate(linear):
            X1, structure, shift = np.asarray(term["matrix"], dtype=float), term["structure"], term["shift"]
            entry = {"name": term["name"], "structure": structure, "shift": shift}
            if structure in ("spd", "psd"):
                S = 0.5 * (X1 + X1.T) - shift * np.eye(X1.shape[0])
                w, Q = np.linalg.eigh(S)
                G1 = (Q * np.sqrt(np.maximum(w, 0.0))) @ Q.T
                entry["base"] = _tensor(G1)
                entry["scale"] = float(max(np.sqrt(max(w.max(), 0.0)), term["floor"]))
            else:
                entry["base"] = _tensor(X1)
                entry["scale"] = float(max(np.sqrt(np.mean(X1 * X1)), term["floor"]))
            if self.config.refine_linear:
                P = torch.nn.Parameter(torch.zeros(X1.shape, dtype=DTYPE))
                self.register_parameter(f"linear_{i}", P)
                entry["parameter"] = P
            self.linear.append(entry)

    def _hysteresis_terms(self, spec: dict | None, scales: dict) -> None:
        r"""The sliders' weights ``k = c_h T (d * d)``, non-negative for any ``d`` (trained).

        ``T`` (p, p) (:func:`slider_maps`) maps non-negative increments to the weights: with a ``top``
        slider ``j``, the shape of Segalman's densities that :class:`~femrom.inference.IwanLOpInf` fits
        (``k_1 <= ... <= k_{j-1}``, ``k_j`` free, nothing above); without one (``monotone`` false)
        ``T = I``. ``c_h``: the force scale over the coordinate scale squared (``d`` of order one).
        The stretches along ``x = a . q^`` are data (the play operator on the data's history), so the
        residual is linear in ``k``: each least-squares stage solves the weights exactly, choosing
        the top slider too (:func:`solve_linear_part`); L-BFGS keeps the top.
        """
        self.hysteresis = None
        if spec is None:
            return
        a = np.asarray(spec["direction"], dtype=float)
        phi = np.asarray(spec["thresholds"], dtype=float)
        scale = float(scales["potential"]) / (float(np.mean(scales["q"])) ** 2 * float(a @ a))
        self.hysteresis = {"direction": _tensor(a), "thresholds": phi, "scale": scale,
                           "monotone": bool(spec.get("monotone", spec.get("top") is not None))}
        self.hysteresis_increments = torch.nn.Parameter(torch.zeros(phi.size, dtype=DTYPE))
        self.set_sliders(spec.get("top"), spec["weights"])

    def set_sliders(self, top: int | None, weights) -> None:
        """Set the weights (p,) in the shape of the ``top`` slider (:func:`slider_maps`)."""
        p = self.hysteresis["thresholds"].size
        self.hysteresis["top"], self.hysteresis["map"] = top, _tensor(slider_maps(p, top))
        y = slider_increments(weights, top)
        with torch.no_grad():
            self.hysteresis_increments.copy_(_tensor(np.sqrt(y / self.hysteresis["scale"])))

    def hysteresis_weights(self) -> torch.Tensor:
        """(p,) the sliders' weights ``k``."""
        d = self.hysteresis_increments
        return self.hysteresis["scale"] * (self.hysteresis["map"] @ (d * d))

    def hysteresis_force(self, stretches: torch.Tensor) -> torch.Tensor:
        """(K, r) ``a sum_i k_i e_i`` at the rows of the stretches (K, p)."""
        return (stretches @ self.hysteresis_weights())[:, None] * self.hysteresis["direction"][None, :]

    def linear_matrices(self) -> list:
        """The linear terms' matrices ``X_j`` (r, p_j), in step 1's order."""
        out = []
        for e in self.linear:
            P, base, c = e.get("parameter"), e["base"], e["scale"]
            if e["structure"] == "spd":
                G = base if P is None else base @ (torch.eye(self.r, dtype=DTYPE) + P)
                X = G @ G.T + e["shift"] * torch.eye(self.r, dtype=DTYPE)
            elif e["structure"] == "psd":
                G = base if P is None else base + c * P
                X = G @ G.T
            elif e["structure"] == "symmetric":
                X = base if P is None else base + 0.5 * c * (P + P.T)
            else:
                X = base if P is None else base + c * P
            out.append(X)
        return out

    def mass_factor(self) -> torch.Tensor:
        """``L`` with ``M^ = L L^T``: ``L0 (I + strict_lower(P) + diag(exp(d) - 1))``, positive diagonal."""
        if not self.config.learn_mass:
            return self.L0
        inner = torch.tril(self.mass_lower, -1) + torch.diag(torch.exp(self.mass_log_diagonal))
        return self.L0 @ inner

    def mass(self) -> torch.Tensor:
        L = self.mass_factor()
        return L @ L.T

    def _u_network(self, x: torch.Tensor, gradient: bool = False) -> torch.Tensor:
        """(K,) ``N(x)``, or with ``gradient`` (K, r) ``grad N(x)`` by the explicit backward pass."""
        hs, h = [], x
        for W, b in zip(self.u_weights, self.u_biases):
            h = torch.tanh(h @ W.T + b)
            hs.append(h)
        if not gradient:
            return h @ self.u_output
        delta = self.u_output.expand_as(h)
        for W, h in zip(reversed(list(self.u_weights)), reversed(hs)):
            delta = (delta * (1.0 - h * h)) @ W
        return delta

    def _f_network(self, w: torch.Tensor, gradient: bool = False) -> torch.Tensor:
        """(K,) the input-convex ``N(w)``, or with ``gradient`` (K, r) ``grad N(w)``."""
        softplus = torch.nn.functional.softplus
        hidden = [softplus(raw) for raw in self.f_hidden_raw]
        z = w @ self.f_input[0].T + self.f_biases[0]
        zs = [z]
        for Wz, U, b in zip(hidden, self.f_input[1:], self.f_biases[1:]):
            z = softplus(z) @ Wz.T + w @ U.T + b
            zs.append(z)
        output = softplus(self.f_output_raw)
        if not gradient:
            return softplus(z) @ output
        delta, grad = output.expand_as(z), torch.zeros_like(w)
        for i in range(len(zs) - 1, -1, -1):
            dz = delta * torch.sigmoid(zs[i])
            grad = grad + dz @ self.f_input[i]
            if i > 0:
                delta = dz @ hidden[i - 1]
        return grad

    def potential(self, q: torch.Tensor) -> torch.Tensor:
        """(K,) ``U^`` at the rows of ``q`` (K, r), up to the network's constant and linear shift."""
        x = q / self.sq
        value = torch.zeros(q.shape[0], dtype=DTYPE)
        for d, index in self.indices.items():
            products = x[:, index[:, 0]]
            for j in range(1, d):
                products = products * x[:, index[:, j]]
            value = value + products @ self.alpha[str(d)]
        if self.u_output is not None:
            value = value + self._u_network(x)
        return self.cU * value

    def dissipation(self, v: torch.Tensor) -> torch.Tensor:
        """(K,) ``F^`` at the rows of ``v`` (K, r), up to the network's constant and linear shift."""
        w = v / self.sv
        value = torch.zeros(v.shape[0], dtype=DTYPE)
        if self.d_cubic is not None:
            value = value + (torch.abs(w @ self.d_cubic.T) ** 3).sum(-1) / 3.0 \
                + ((w @ self.d_quartic.T) ** 4).sum(-1) / 4.0
        if self.f_output_raw is not None:
            value = value + self._f_network(w)
        return self.cF * value

    # -- the forces: exact gradients of the two scalars, by explicit backward passes ------
    def features(self, q: torch.Tensor) -> dict:
        """The monomials of degree ``d - 1`` of ``x = q / s_q`` (K, n_{d-1}), fixed data: the
        gradient of ``sum_m alpha_m x^m`` is ``Phi_{d-1}(x) A(alpha)``, linear in ``alpha``."""
        x = (q / self.sq).numpy()
        return {d: _tensor(monomials(x, d - 1)) for d in self.indices}

    def _derivative_map(self, d: int):
        if d not in self._maps:
            m, p, i, e = (torch.as_tensor(c) for c in derivative_map(self.r, d))
            self._maps[d] = (m, p, i, e.to(DTYPE))
        return self._maps[d]

    def potential_force(self, q: torch.Tensor, features: dict) -> torch.Tensor:
        r"""(K, r) ``dU^/dq`` at the rows of ``q``:
        ``c_U / s_q * (sum_d Phi_{d-1} A_d(alpha) + grad N(x) - grad N(0))``."""
        x = q / self.sq
        grad = torch.zeros_like(q)
        for d in self.indices:
            m, p, i, e = self._derivative_map(d)
            A = torch.zeros((int(features[d].shape[1]), self.r), dtype=DTYPE).index_put(
                (p, i), self.alpha[str(d)][m] * e, accumulate=True)
            grad = grad + features[d] @ A
        if self.u_output is not None:
            grad = grad + self._u_network(x, True) - self._u_network(torch.zeros((1, self.r), dtype=DTYPE), True)
        return self.cU * grad / self.sq

    def dissipation_force(self, v: torch.Tensor) -> torch.Tensor:
        """(K, r) ``dF^/dv`` at the rows of ``v``."""
        w = v / self.sv
        grad = torch.zeros_like(v)
        if self.d_cubic is not None:
            s, t = w @ self.d_cubic.T, w @ self.d_quartic.T
            grad = grad + (torch.abs(s) * s) @ self.d_cubic + (t ** 3) @ self.d_quartic
        if self.f_output_raw is not None:
            grad = grad + self._f_network(w, True) - self._f_network(torch.zeros((1, self.r), dtype=DTYPE), True)
        return self.cF * grad / self.sv

    def gauge(self) -> torch.Tensor:
        r"""``(log(tr M^ / tr M_0))^2`` when the mass and the linear terms are both learned.

        The residual :meth:`residual` is unchanged when every term is scaled by one
        factor ``s`` (mass, stiffness, damping, inputs, potential, dissipation): the data
        leave that scale free. This penalty fixes it at ``tr M^ = tr M_0`` and, being zero
        there, biases nothing else.
        """
        if not (self.config.learn_mass and self.config.refine_linear):
            return torch.zeros((), dtype=DTYPE)
        L, L0 = self.mass_factor(), self.L0
        return torch.log((L * L).sum() / (L0 * L0).sum()) ** 2

    @property
    def has_potential(self) -> bool:
        return self.u_output is not None or bool(self.indices)

    @property
    def has_dissipation(self) -> bool:
        return self.dissipative and (self.d_cubic is not None or self.f_output_raw is not None)

    def residual(self, q, v, a, target, blocks, features, stretches=None) -> torch.Tensor:
        r"""(K, r) ``M^^-1 (Y + (M^ - M_0) a + sum_j D_j^T X_j^T + dF^/dv + dU^/dq + a_h k^T e)`` (rows).

        ``Y`` (K, r): step 1's target (``M_0 a`` and the known terms); ``blocks``: the
        learned linear terms' data blocks ``D_j^T`` (K, p_j) (``q``, ``v``, ``-u``, ...);
        ``features``: :meth:`features` of ``q``; ``stretches`` (K, p): the sliders' (with
        :attr:`hysteresis`). Solved with ``M^``, the residual is an
        acceleration: scaling every term by one factor leaves it unchanged, so a learned
        mass cannot shrink the loss by shrinking the model.
        """
        R = target + a @ (self.mass() - self.L0 @ self.L0.T).T
        for X, D in zip(self.linear_matrices(), blocks):
            R = R + D @ X.T
        if self.has_potential:
            R = R + self.potential_force(q, features)
        if self.has_dissipation:
            R = R + self.dissipation_force(v)
        if self.hysteresis is not None:
            R = R + self.hysteresis_force(stretches)
        L = self.mass_factor()
        return torch.linalg.solve_triangular(L.T, torch.linalg.solve_triangular(L, R.T, upper=False),
                                             upper=True).T

    # -- export -------------------------------------------------------------------------
    def export(self):
        """``(mass (r, r), linear {name: X_j}, polynomial, u_network, powers, f_network)``: numpy, unscaled
        (the sliders' weights: :meth:`hysteresis_weights`)."""
        sq, sv = self.sq.numpy(), self.sv.numpy()
        with torch.no_grad():
            mass = self.mass().numpy().copy()
            mass = 0.5 * (mass + mass.T)
            polynomial = None
            if self.indices:
                terms = {}
                for d, index in self.indices.items():
                    idx = index.numpy()
                    terms[d] = (idx, self.cU * self.alpha[str(d)].numpy() / np.prod(sq[idx], axis=1))
                polynomial = SymmetricPolynomial(self.r, terms)
            u_network = None
            if self.u_output is not None and bool(torch.any(self.u_output != 0)):   # a pruned one costs, adds 0
                layers = [NetworkLayer(self.u_biases[0].numpy().copy(), None, self.u_weights[0].numpy() / sq)]
                layers += [NetworkLayer(b.numpy().copy(), W.numpy().copy()) for W, b in
                           zip(self.u_weights[1:], self.u_biases[1:])]
                u_network = ScalarNetwork(layers, self.cU * self.u_output.numpy(), "tanh")
            powers = None
            if self.d_cubic is not None and bool(torch.any(self.d_cubic != 0) or torch.any(self.d_quartic != 0)):
                powers = ConvexPowers(self.cF ** (1 / 3) * self.d_cubic.numpy() / sv,
                                      self.cF ** 0.25 * self.d_quartic.numpy() / sv)
            f_network = None
            # switched off (:func:`prune`): softplus(-40) = 4e-18 of the force scale, below round-off
            if self.f_output_raw is not None and float(self.f_output_raw.max()) > PRUNED:
                softplus = torch.nn.functional.softplus
                layers = [NetworkLayer(self.f_biases[0].numpy().copy(), None, self.f_input[0].numpy() / sv)]
                layers += [NetworkLayer(b.numpy().copy(), softplus(raw).numpy().copy(), U.numpy() / sv)
                           for raw, U, b in zip(self.f_hidden_raw, self.f_input[1:], self.f_biases[1:])]
                f_network = ScalarNetwork(layers, self.cF * softplus(self.f_output_raw).numpy(), "softplus")
            linear = {e["name"]: X.numpy().copy() for e, X in zip(self.linear, self.linear_matrices())}
        return mass, linear, polynomial, u_network, powers, f_network


def train(module: SpMLModule, train_arrays, validation_arrays, config, progress, rollouts=None) -> dict:
    r"""Fit the module's weights in stages (:func:`_stages`) and return what each did.

    ``train_arrays``/``validation_arrays``: ``(q, v, a, Y, blocks, ||Y||_F^2, stretches)`` with (K, r)
    arrays, a list of (K, p_j) blocks and the sliders' (K, p) stretches or ``None``
    (:meth:`SpMLModule.residual`); ``rollouts``: ``(training,
    validation or None)`` trajectory lists for the rollout refinement (:class:`Rollout`). Runs on ``config.threads``
    torch threads (restored after): at these sizes intra-op threads cost more than they give
    (measured on 2 shared cores: a (9000, 3) x (3, 16) product took 26 ms on 2 threads, 0.36 ms on 1).
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(int(config.threads))
    try:
        return _stages(module, train_arrays, validation_arrays, config, progress, rollouts)
    finally:
        torch.set_num_threads(threads)


def _loss_on(module, arrays) -> float:
    q, v, a, Y, blocks, features, norm, stretches = arrays
    with torch.no_grad():
        R = module.residual(q, v, a, Y, blocks, features, stretches)
        return float((R * R).sum() / norm)


def _tensors(module, arrays):
    if arrays is None:
        return None
    q = _tensor(arrays[0])
    return (q, *(_tensor(x) for x in arrays[1:4]), [_tensor(D) for D in arrays[4]], module.features(q),
            float(arrays[5]), None if arrays[6] is None else _tensor(arrays[6]))


def _snapshot(module) -> dict:
    return {"state": {k: v.detach().clone() for k, v in module.state_dict().items()},
            "bases": [e["base"].clone() for e in module.linear],
            "top": None if module.hysteresis is None else module.hysteresis["top"]}


def _restore(module, snapshot: dict) -> None:
    module.load_state_dict(snapshot["state"])
    for e, base in zip(module.linear, snapshot["bases"]):
        e["base"] = base.clone()
    if module.hysteresis is not None:         # the weights' shape (the parameters are the increments)
        top = snapshot["top"]
        module.hysteresis["top"] = top
        module.hysteresis["map"] = _tensor(slider_maps(module.hysteresis["thresholds"].size, top))


def _stages(module, train_arrays, validation_arrays, config, progress, rollouts=None) -> dict:
    r"""Least squares, L-BFGS, least squares again: each stage kept only if the checked loss falls.

    The checked loss is the validation trajectory's (the training loss without one).

    1. ``least_squares``: :func:`solve_linear_part` from step 1's values twice, with the
       networks and convex powers as initialised and with them switched off (:func:`prune`); the
       best of the two and of step 1's start is kept (``polynomial_start`` drops step 1's start).
    2. L-BFGS (:func:`_train`) on every weight from there, at most ``max_iterations``.
    3. ``least_squares_rounds - 1`` more solves of the linear part (kept, pruned) with the
       networks where L-BFGS left them, each followed by L-BFGS on the remaining budget, while a
       solve improves the checked loss by ``tolerance``.
    4. With ``rollout_steps``: L-BFGS on the rollout loss (:class:`Rollout`, :func:`refine_rollout`),
       checked on the validation trajectory's windows.
    """
    train_t = _tensors(module, train_arrays)
    valid_t = _tensors(module, validation_arrays)

    def score():
        return _loss_on(module, valid_t if valid_t is not None else train_t)

    stages, history, iterations = [], [], 0

    def record(name, tic, **extra):
        stages.append({"stage": name, "seconds": time.perf_counter() - tic, "loss": _loss_on(module, train_t),
                       "validation_loss": None if valid_t is None else _loss_on(module, valid_t), **extra})

    def solve_from(start: dict):
        """Candidates of one least-squares round from ``start``: (score, snapshot)."""
        out, cache = [], {}
        for pruned in (False, True):
            _restore(module, start)
            if pruned:
                prune(module)
            solve_linear_part(module, train_arrays, train_t[5], config.polynomial_ridge, cache=cache)
            out.append((score(), _snapshot(module), pruned))
        return out

    tic = time.perf_counter()
    record("step 1", tic)
    if config.least_squares or config.polynomial_start:
        tic = time.perf_counter()
        start = _snapshot(module)
        candidates = solve_from(start)
        if not config.polynomial_start:
            _restore(module, start)
            candidates.append((score(), start, None))
        best = min(candidates, key=lambda c: c[0])
        _restore(module, best[1])
        record("least squares", tic, pruned=best[2])
    rounds = max(int(config.least_squares_rounds), 1) if (config.least_squares or config.polynomial_start) else 1
    for k in range(rounds):
        budget = int(config.max_iterations) - iterations
        if budget <= 0:
            break
        tic = time.perf_counter()
        result = _train(module, train_t, valid_t, replace(config, max_iterations=budget), progress, offset=iterations)
        history += result["history"]
        iterations = result["iterations"]
        record("L-BFGS", tic, iterations=result["iterations"])
        if k == rounds - 1:
            break
        tic = time.perf_counter()
        current = (score(), _snapshot(module), None)
        best = min(solve_from(current[1]) + [current], key=lambda c: c[0])
        _restore(module, best[1])
        record("least squares", tic, pruned=best[2])
        if not best[0] < current[0] * (1.0 - config.tolerance):
            break
    if rollouts is not None:
        tic = time.perf_counter()
        make = [None if t is None else Rollout(module, t, config.rollout_steps, config.rollout_substeps,
                                               config.rollout_stride) for t in rollouts]
        checked = make[1] if make[1] is not None else make[0]
        with torch.no_grad():
            before = float(checked.loss())
        result = refine_rollout(module, make[0], make[1], config, progress, iterations)
        history += result["history"]
        iterations = result["iterations"]
        record("rollout", tic, iterations=result["iterations"], rollout_loss_before=before,
               rollout_loss=result["best_loss"])
    best_iteration = max((h["iteration"] for h in history if h.get("kept")), default=0)
    return {"history": history, "best_iteration": best_iteration, "best_loss": score(),
            "iterations": iterations, "stages": stages}


def _train(module, train_t, valid_t, config, progress, offset: int = 0, objective=None) -> dict:
    """Full-batch L-BFGS on every weight, at most ``config.max_iterations`` (module docstring of
    :func:`train`): every ``check_every`` iterations the checked loss is compared with the best so
    far (the start's included), the best weights are kept, and training stops after ``patience``
    checks without a relative improvement of ``tolerance``; when L-BFGS stops on its own it is
    restarted once with a fresh memory. ``offset``: iterations done before (for the history);
    ``objective``: the loss of an arrays tuple (default: the relative residual)."""
    parameters = [p for p in module.parameters() if p.requires_grad]

    def lbfgs():
        return torch.optim.LBFGS(parameters, lr=1.0, max_iter=config.check_every,
                                 history_size=config.history_size, line_search_fn="strong_wolfe",
                                 tolerance_grad=1e-14, tolerance_change=1e-16)

    optimizer = lbfgs()
    decay = [p for name, p in module.named_parameters() if "weights" in name or "input" in name or "raw" in name]

    def loss_of(arrays):
        if objective is not None:
            return objective(arrays)
        q, v, a, Y, blocks, features, norm, stretches = arrays
        R = module.residual(q, v, a, Y, blocks, features, stretches)
        return (R * R).sum() / norm

    def closure():
        optimizer.zero_grad()
        loss = loss_of(train_t) + module.gauge()
        if config.weight_decay:
            loss = loss + config.weight_decay * sum((p * p).sum() for p in decay)
        loss.backward()
        return loss

    def score():
        arrays = valid_t if valid_t is not None else train_t
        with torch.no_grad():
            return float(loss_of(arrays))

    history = []
    best = {"loss": score(), "iteration": offset, "state": _snapshot(module)}
    stale, iterations, restart, stalled = 0, 0, 0, False
    while iterations < config.max_iterations:
        optimizer.step(closure)
        done = restart + int(optimizer.state[parameters[0]].get("n_iter", 0))
        step_iterations = max(done - iterations, 1)
        iterations = done
        with torch.no_grad():
            train_loss = float(loss_of(train_t))
        check = score()
        history.append({"iteration": offset + iterations, "loss": train_loss, "validation_loss": check,
                        "kept": False})
        progress.label = f"SpML fit: loss {train_loss:.3e}" + (f", validation {check:.3e}" if valid_t else "")
        progress.update(step_iterations)
        if not np.isfinite(check):
            break
        if check < best["loss"] * (1.0 - config.tolerance):
            best = {"loss": check, "iteration": offset + iterations, "state": _snapshot(module)}
            history[-1]["kept"] = True
            stale = 0
        else:
            stale += 1
            if stale >= config.patience:
                break
        if step_iterations < config.check_every:
            # L-BFGS stopped on its own (no step along its direction changes the loss): once
            # with a fresh memory, and if that stalls at once too, the fit has converged
            if stalled:
                break
            stalled, restart, optimizer = True, iterations, lbfgs()
        else:
            stalled = False
    _restore(module, best["state"])
    return {"history": history, "best_iteration": best["iteration"], "best_loss": best["loss"],
            "iterations": offset + iterations}


# -- the part linear in the parameters, solved exactly ----------------------------------------------
def _unknowns(structure: str, r: int, p: int) -> list:
    if structure in ("spd", "psd", "symmetric"):
        return [(i, j) for i in range(r) for j in range(i, r)]
    return [(i, j) for i in range(r) for j in range(p)]


def _matrix_block(D: np.ndarray, structure: str, r: int) -> np.ndarray:
    """(k, r, n) the residual's derivative in the unknowns of ``X`` in ``D @ X.T`` (symmetric: pairs)."""
    pairs = _unknowns(structure, r, D.shape[1])
    block = np.zeros((D.shape[0], r, len(pairs)))
    for c, (i, j) in enumerate(pairs):
        block[:, i, c] += D[:, j]
        if structure != "free" and i != j:
            block[:, j, c] += D[:, i]
    return block


def _matrix_of(theta: np.ndarray, structure: str, shape) -> np.ndarray:
    X = np.zeros(shape)
    for c, (i, j) in enumerate(_unknowns(structure, shape[0], shape[1])):
        X[i, j] = theta[c]
        if structure != "free":
            X[j, i] = theta[c]
    return X


def _cone(X: np.ndarray, structure: str, floor: float) -> np.ndarray:
    if structure not in ("spd", "psd"):
        return X
    w, U = np.linalg.eigh(0.5 * (X + X.T))
    return (U * np.maximum(w, floor)) @ U.T


def fixed_forces(module: SpMLModule, q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """(K, r) the forces of the networks and the convex powers (what the linear solve keeps fixed)."""
    with torch.no_grad():
        out = torch.zeros_like(q)
        if module.u_output is not None:
            zero = torch.zeros((1, module.r), dtype=DTYPE)
            x = q / module.sq
            out = out + module.cU * (module._u_network(x, True) - module._u_network(zero, True)) / module.sq
        if module.has_dissipation:
            out = out + module.dissipation_force(v)
    return out


def prune(module: SpMLModule) -> None:
    """Switch the networks and the convex powers off (the potential network's output to 0, which
    training can move again; the dissipation's powers and output to 0 and ``softplus(-40)``, which it
    cannot: their gradients vanish there)."""
    with torch.no_grad():
        if module.u_output is not None:
            module.u_output.zero_()
        if module.d_cubic is not None:
            module.d_cubic.zero_()
            module.d_quartic.zero_()
        if module.f_output_raw is not None:
            module.f_output_raw.fill_(PRUNED_RAW)


def solve_linear_part(module: SpMLModule, arrays, features: dict, ridge: float, chunk: int = 2048,
                      cache: dict | None = None) -> None:
    r"""Set the parameters that enter the residual linearly to their least-squares values, the rest fixed.

    With the networks and the convex powers fixed, the residual
    ``R = Y + (M^ - M_0) Q'' + sum_j D_j X_j^T + Phi(Q) alpha + f_fixed`` is linear in the mass ``M^``
    (symmetric; when learned), the linear terms ``X_j`` (symmetric ones by their upper triangles) and
    the monomials' coefficients ``alpha``. The loss ``||M^^-1 R||_F^2`` is weighted by the current
    mass; the solve minimises ``||W R||_F^2`` with ``W = M_cur^-1`` subject to ``tr M^ = tr M_0`` (the
    gauge), by its normal equations accumulated over column chunks (KKT system for the
    constraint) with a relative Tikhonov weight ``ridge`` per block (monomials of one degree, one
    matrix). ``M^`` and the ``spd``/``psd`` terms are projected back onto their cones (eigenvalues
    clipped at ``eps``, 0, or 1e-8 of the mass's largest); the coefficients ``alpha`` are then solved
    again with the matrices fixed. The module's parameters are set in place (the linear terms are
    re-based: their starting matrix becomes the solution and the correction ``P`` restarts at 0).
    """
    q, v, a, Y, blocks, _, stretches = arrays
    K, r = q.shape
    sliders = module.hysteresis
    if sliders is not None:             # the weights' increments y >= 0: a (K, n_d) data block E T
        direction, slider_data = sliders["direction"].numpy(), stretches
    n_sliders = 0 if sliders is None else slider_data.shape[1]
    if n_sliders:                       # the shapes tried: every top slider, or non-negative weights
        tops = list(range(n_sliders)) if sliders["monotone"] else [None]
        shapes, chosen = [slider_maps(n_sliders, top) for top in tops], []
    with torch.no_grad():
        M_cur = module.mass().numpy()
        M0 = (module.L0 @ module.L0.T).numpy()
    W = np.linalg.inv(M_cur)
    fixed = fixed_forces(module, _tensor(q), _tensor(v)).numpy()
    degrees = list(module.indices)
    maps = {d: module._derivative_map(d) for d in degrees}
    sizes = [len(module.indices[d]) for d in degrees]
    learn_mass = bool(module.config.learn_mass)
    refine = bool(module.config.refine_linear)
    scale = module.cU / float(module.sq[0])        # isotropic scales (:func:`_scales`)

    def poly_block(rows):
        parts = []
        for d, n in zip(degrees, sizes):
            m, p, i, e = (t.numpy() for t in maps[d])
            Phi = features[d][rows].numpy()
            block = np.zeros((Phi.shape[0], r, n))
            np.add.at(block, (slice(None), i, m), scale * e[None, :] * Phi[:, p])
            parts.append(block)
        return parts

    def accumulate(with_matrices: bool, constant):
        """Normal equations; the Gram matrix depends on the weight only, so ``cache`` keeps it for the
        next candidate of the same round."""
        key = (W.tobytes(), with_matrices)
        if cache is not None and key in cache:
            G, widths, design = cache[key]
            h = sum(A.T @ (constant[rows] @ W.T).ravel() for rows, A in design)
            return G, h, widths
        G, h, widths, design = np.zeros((0, 0)), np.zeros(0), [], []
        for start in range(0, K, chunk):
            rows = slice(start, start + chunk)
            parts = poly_block(rows)
            if with_matrices:
                if learn_mass:
                    parts.append(_matrix_block(a[rows], "symmetric", r))
                if refine:
                    parts += [_matrix_block(D[rows], e["structure"], r) for e, D in zip(module.linear, blocks)]
            if n_sliders:
                parts.append(direction[None, :, None] * slider_data[rows][:, None, :])
            widths = [p.shape[2] for p in parts]
            if not widths:
                return G, h, widths
            A = np.einsum("ij,kjp->kip", W, np.concatenate(parts, axis=2)).reshape(-1, sum(widths))
            b = (constant[rows] @ W.T).ravel()
            G, h = (A.T @ A, A.T @ b) if G.size == 0 else (G + A.T @ A, h + A.T @ b)
            design.append((rows, A))
        if cache is not None:
            cache[key] = (G, widths, design)
        return G, h, widths

    def solve(G, h, widths, constraint=None):
        d = np.diag(G)
        reg, start = np.zeros(G.shape[0]), 0
        for width in widths:
            block = slice(start, start + width)
            reg[block] = ridge * max(float(np.mean(d[block])), np.finfo(float).tiny)
            start += width
        A = G + np.diag(reg)
        if n_sliders:                   # the last n_sliders unknowns: the weights, in one of their shapes
            theta, index = _bounded_solve(A, h, shapes, constraint)
            chosen.append(tops[index])
            return theta
        if constraint is None:
            return -np.linalg.lstsq(A, h, rcond=None)[0]
        c, value = constraint
        n = A.shape[0]
        kkt = np.block([[A, c[:, None]], [c[None, :], np.zeros((1, 1))]])
        return np.linalg.lstsq(kkt, np.concatenate([-h, [value]]), rcond=None)[0][:n]

    base = Y - a @ M0.T + fixed                     # R = base + a M^T + sum D X^T + Phi alpha
    if not refine and module.linear:                # the linear terms stay: on the constant's side
        base = base + sum(D @ X.detach().numpy().T for X, D in zip(module.linear_matrices(), blocks))
    matrices = {}
    widths = []
    if learn_mass or refine:
        G, h, widths = accumulate(True, base if learn_mass else base + a @ M_cur.T)
    if widths:
        npoly = sum(sizes)
        constraint = None
        if learn_mass:
            pairs = _unknowns("symmetric", r, r)
            c = np.zeros(G.shape[0])
            for k, (i, j) in enumerate(pairs):
                if i == j:
                    c[npoly + k] = 1.0
            constraint = (c, float(np.trace(M0)))
        theta = solve(G, h, widths, constraint)
        start = npoly
        if learn_mass:
            n = r * (r + 1) // 2
            M = _matrix_of(theta[start:start + n], "symmetric", (r, r))
            matrices["mass"] = _cone(M, "spd", 1e-8 * max(np.linalg.eigvalsh(M).max(), 1e-300))
            start += n
        if refine:
            for e, D in zip(module.linear, blocks):
                n = len(_unknowns(e["structure"], r, D.shape[1]))
                X = _matrix_of(theta[start:start + n], e["structure"], (r, D.shape[1]))
                matrices[e["name"]] = _cone(X, e["structure"], e["shift"] if e["structure"] == "spd" else 0.0)
                start += n
    # the coefficients again, the (projected) matrices fixed
    M = matrices.get("mass", M_cur)
    constant = base + a @ M.T
    if refine and module.linear:
        constant = constant + sum(D @ matrices[e["name"]].T for e, D in zip(module.linear, blocks))
    alpha, increments = np.zeros(0), None
    if degrees or n_sliders:
        G, h, widths = accumulate(False, constant)
        theta = solve(G, h, widths)
        alpha = theta[:sum(sizes)]
        if n_sliders:
            increments = (chosen[-1], theta[sum(sizes):])
    elif not matrices:
        return
    _set(module, alpha, degrees, sizes, matrices, increments)


def slider_maps(p: int, top: int | None) -> np.ndarray:
    """(p, p) ``T`` with the sliders' weights ``k = T y``, ``y >= 0``: with a ``top`` slider ``j``,
    ``k_i = sum_{l <= i} y_l`` for ``i < j`` (nondecreasing), ``k_j = y_j``, nothing above; ``None``: ``I``."""
    if top is None:
        return np.eye(p)
    T = np.zeros((p, p))
    for i in range(top):
        T[i, :i + 1] = 1.0
    T[top, top] = 1.0
    return T


def slider_increments(k: np.ndarray, top: int | None) -> np.ndarray:
    """(p,) ``y >= 0`` with ``k = slider_maps(p, top) y`` for weights ``k`` of that shape (round-off clipped)."""
    k = np.clip(np.asarray(k, dtype=float), 0.0, None)
    if top is None:
        return k
    y = np.zeros_like(k)
    y[:top] = np.clip(np.diff(k[:top], prepend=0.0), 0.0, None)
    y[top] = k[top]
    return y


def _bounded_solve(A: np.ndarray, h: np.ndarray, maps: list, constraint=None) -> tuple[np.ndarray, int]:
    r"""``argmin theta^T A theta / 2 + h^T theta`` over every shape of the last ``p`` unknowns (the
    sliders' weights ``k = T y``, ``y >= 0``, one ``T`` (p, p) of ``maps`` at a time), with
    ``c . theta = value`` given ``constraint = (c, value)`` (``c`` zero on the weights); returns the
    best ``theta`` (the weights in it) and the index of its map.

    The constraint is eliminated through the unknown where ``c`` is largest; the unbounded unknowns
    ``u`` are then eliminated too (``u = -A_uu^-1 (g_u + A_uk k)``), leaving for each map a problem
    in the ``p`` increments, ``min y^T T^T S T y / 2 + (T^T g)^T y``, ``y >= 0`` with the Schur
    complement ``S``: a non-negative least-squares problem of ``p`` unknowns (scipy's NNLS).
    """
    from scipy.optimize import nnls

    n, p = A.shape[0], maps[0].shape[0]
    if constraint is None:
        Z, theta0 = np.eye(n), np.zeros(n)
    else:
        c, value = constraint
        m = int(np.argmax(np.abs(c)))
        keep = [i for i in range(n) if i != m]
        Z = np.zeros((n, n - 1))
        Z[keep, np.arange(n - 1)] = 1.0
        Z[m] = -c[keep] / c[m]
        theta0 = np.zeros(n)
        theta0[m] = value / c[m]
    Az = Z.T @ A @ Z
    g = Z.T @ (A @ theta0 + h)
    nu = Az.shape[0] - p
    Auu, Auk, Akk = Az[:nu, :nu], Az[:nu, nu:], Az[nu:, nu:]
    if nu:
        solved = np.linalg.lstsq(Auu, np.column_stack([Auk, g[:nu]]), rcond=None)[0]
        S, gk = Akk - Auk.T @ solved[:, :p], g[nu:] - Auk.T @ solved[:, p]
    else:
        S, gk = Akk, g
    S = 0.5 * (S + S.T)
    best = None
    for index, T in enumerate(maps):
        St, gt = T.T @ S @ T, T.T @ gk
        w, U = np.linalg.eigh(St)
        keep = w > 1e-13 * max(float(w.max()), np.finfo(float).tiny)
        # ||D U^T y + D^-1 U^T g||^2 / 2 = y^T St y / 2 + g^T y + const on the kept eigenvectors
        D = np.sqrt(w[keep])
        y = nnls((D[:, None] * U[:, keep].T), -(U[:, keep].T @ gt) / D, maxiter=50 * p)[0]
        value_ = 0.5 * y @ St @ y + gt @ y
        if best is None or value_ < best[0]:
            best = (value_, index, T @ y)
    _, index, k = best
    u = -solved[:, p] - solved[:, :p] @ k if nu else np.zeros(0)
    return theta0 + Z @ np.concatenate([u, k]), index


def _set(module: SpMLModule, alpha, degrees, sizes, matrices: dict, increments=None) -> None:
    with torch.no_grad():
        if increments is not None:
            module.set_sliders(*increments)
        start = 0
        for d, n in zip(degrees, sizes):
            module.alpha[str(d)].copy_(_tensor(alpha[start:start + n]))
            start += n
        if "mass" in matrices:
            inner = np.linalg.solve(module.L0.numpy(), np.linalg.cholesky(matrices["mass"]))
            module.mass_lower.copy_(_tensor(np.tril(inner, -1)))
            module.mass_log_diagonal.copy_(_tensor(np.log(np.diag(inner))))
        for e in module.linear:
            if e["name"] not in matrices:
                continue
            X = matrices[e["name"]]
            if e["structure"] in ("spd", "psd"):
                S = 0.5 * (X + X.T) - e["shift"] * np.eye(X.shape[0])
                w, Q = np.linalg.eigh(S)
                e["base"] = _tensor((Q * np.sqrt(np.maximum(w, 0.0))) @ Q.T)
            else:
                e["base"] = _tensor(X)
            if "parameter" in e:
                e["parameter"].zero_()


# -- the rollout refinement: trajectories through the discrete-gradient step -------------------------
def _monomials_t(x: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    out = torch.ones((x.shape[0], index.shape[0]), dtype=DTYPE)
    for j in range(index.shape[1]):
        out = out * x[:, index[:, j]]
    return out


def _potential_force_t(module: SpMLModule, q: torch.Tensor) -> torch.Tensor:
    """(B, r) ``dU^/dq`` at the rows of ``q``, differentiable in ``q`` too (the monomials computed in torch)."""
    x = q / module.sq
    features = {d: _monomials_t(x, torch.as_tensor(multi_indices(module.r, d - 1))) for d in module.indices}
    return module.potential_force(q, features)


class Rollout:
    r"""Windows of a trajectory predicted by the discrete-gradient step, differentiable in the weights.

    From every ``stride``-th sample ``(q_k, v_k)`` of each trajectory, ``steps`` samples ahead,
    each sample interval in ``substeps`` steps of the implicit midpoint rule with the average-vector-field
    discrete gradient of ``U^`` (two-point Gauss-Legendre, exact for the monomials; Gonzalez's
    correction, which the ROM applies to a network's potential, is left out: its size is the
    quadrature's ``O(|Delta|^5)``), ``newton`` fixed-point iterations preconditioned by the linear
    step matrix ``(2/h) M^ + C^ + (h/2) K^`` and unrolled for autograd. The loss is
    ``sum ||q - q_data||^2 / s_q^2 + ||v - v_data||^2 / s_v^2`` over the windows' samples, divided
    by its value for a model that stays at rest. Inputs at a step's midpoint are linear
    interpolations of the samples'.
    """

    def __init__(self, module: SpMLModule, trajectories: list, steps: int, substeps: int, stride: int,
                 newton: int = 4):
        if module.hysteresis is not None:
            raise FemromValueError("SpMLConfig.rollout_steps: the rollout refinement does not step learned sliders")
        self.module, self.steps, self.substeps, self.newton = module, int(steps), int(substeps), int(newton)
        starts, q, v, u, dts = [], [], [], [], []
        for tr in trajectories:
            n = tr["q"].shape[1]
            for k in range(0, n - self.steps, int(stride)):
                starts.append(len(q))
                q.append(tr["q"][:, k:k + self.steps + 1].T)
                v.append(tr["v"][:, k:k + self.steps + 1].T)
                u.append(None if tr.get("u") is None else tr["u"][:, k:k + self.steps + 1].T)
                dts.append(tr["dt"])
        if not q:
            raise FemromValueError(f"no rollout windows: every trajectory is shorter than the window of "
                                   f"{self.steps} steps (rollout_steps)")
        self.q = _tensor(np.stack(q))                  # (B, steps + 1, r)
        self.v = _tensor(np.stack(v))
        self.u = None if u[0] is None else _tensor(np.stack(u))
        self.h = _tensor(np.array(dts))[:, None] / self.substeps     # (B, 1)
        self.sq, self.sv = float(module.sq[0]), float(module.sv[0])
        self.norm = float(((self.q[:, 1:] / self.sq) ** 2).sum() + ((self.v[:, 1:] / self.sv) ** 2).sum())
        self.names = [e["name"] for e in module.linear]

    def _matrices(self):
        m = self.module
        out = dict(zip(self.names, m.linear_matrices()))
        return m.mass(), out.get("stiffness"), out.get("damping"), out.get("input")

    def predict(self):
        """(q, v) (B, steps + 1, r): the windows predicted from their first samples."""
        m = self.module
        M, K, C, B = self._matrices()
        r = m.r
        q, v = self.q[:, 0], self.v[:, 0]
        qs, vs = [q], [v]
        h = self.h
        eye = torch.eye(r, dtype=DTYPE)
        for k in range(self.steps):
            for j in range(self.substeps):
                force = None
                if B is not None and self.u is not None:
                    s = (j + 0.5) / self.substeps
                    u_mid = (1 - s) * self.u[:, k] + s * self.u[:, k + 1]
                    force = u_mid @ B.T
                # the linear step matrix per window (h may differ between trajectories)
                J = (2.0 / h)[:, :, None] * M + (0.5 * h)[:, :, None] * (K if K is not None else 0 * eye)
                if C is not None:
                    J = J + C
                x = v
                for _ in range(self.newton):
                    G = self._residual(M, K, C, force, q, v, x, h)
                    x = x - torch.linalg.solve(J, G)
                q = q + h * x
                v = 2.0 * x - v
            qs.append(q)
            vs.append(v)
        return torch.stack(qs, 1), torch.stack(vs, 1)

    def _residual(self, M, K, C, force, q, v, x, h):
        m = self.module
        q1 = q + h * x
        G = (2.0 / h) * (x - v) @ M.T
        if K is not None:
            G = G + (q + 0.5 * h * x) @ K.T
        if C is not None:
            G = G + x @ C.T
        if force is not None:
            G = G - force
        if m.has_potential:
            delta = q1 - q
            G = G + 0.5 * sum(_potential_force_t(m, q + s * delta) for s in (0.5 - 0.5 / np.sqrt(3.0),
                                                                              0.5 + 0.5 / np.sqrt(3.0)))
        if m.has_dissipation:
            G = G + m.dissipation_force(x)
        return G

    def loss(self) -> torch.Tensor:
        q, v = self.predict()
        return (((q[:, 1:] - self.q[:, 1:]) / self.sq) ** 2).sum() / self.norm \
            + (((v[:, 1:] - self.v[:, 1:]) / self.sv) ** 2).sum() / self.norm


def refine_rollout(module: SpMLModule, train: Rollout, validation: Rollout | None, config, progress,
                   offset: int) -> dict:
    """L-BFGS on the rollout loss (:class:`Rollout`), checked on the validation windows (the training
    ones without), the best weights kept (the start's included), at most ``config.rollout_iterations``."""
    return _train(module, train, validation, replace(config, max_iterations=int(config.rollout_iterations)),
                  progress, offset=offset, objective=lambda rollout: rollout.loss())
