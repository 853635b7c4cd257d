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

import numpy as np
import torch

from femrom.inference._networks import (ConvexPowers, NetworkLayer, ScalarNetwork, SymmetricPolynomial, derivative_map,
                                       monomials, multi_indices)

DTYPE = torch.float64


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
    """

    def __init__(self, r: int, config, scales: dict, mass0: np.ndarray, linear: list, generator: torch.Generator,
                 initial: dict | None = None):
        super().__init__()
        self.r, self.config = r, config
        self._linear_terms(linear)
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

    def residual(self, q, v, a, target, blocks, features) -> torch.Tensor:
        r"""(K, r) ``M^^-1 (Y + (M^ - M_0) a + sum_j D_j^T X_j^T + dF^/dv + dU^/dq)`` (rows).

        ``Y`` (K, r): step 1's target (``M_0 a`` and the known terms); ``blocks``: the
        learned linear terms' data blocks ``D_j^T`` (K, p_j) (``q``, ``v``, ``-u``, ...);
        ``features``: :meth:`features` of ``q``. Solved with ``M^``, the residual is an
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
        L = self.mass_factor()
        return torch.linalg.solve_triangular(L.T, torch.linalg.solve_triangular(L, R.T, upper=False),
                                             upper=True).T

    # -- export -------------------------------------------------------------------------
    def export(self):
        """``(mass (r, r), linear {name: X_j}, polynomial, u_network, powers, f_network)``: numpy, unscaled."""
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
            if self.u_output is not None:
                layers = [NetworkLayer(self.u_biases[0].numpy().copy(), None, self.u_weights[0].numpy() / sq)]
                layers += [NetworkLayer(b.numpy().copy(), W.numpy().copy()) for W, b in
                           zip(self.u_weights[1:], self.u_biases[1:])]
                u_network = ScalarNetwork(layers, self.cU * self.u_output.numpy(), "tanh")
            powers = None
            if self.d_cubic is not None:
                powers = ConvexPowers(self.cF ** (1 / 3) * self.d_cubic.numpy() / sv,
                                      self.cF ** 0.25 * self.d_quartic.numpy() / sv)
            f_network = None
            if self.f_output_raw is not None:
                softplus = torch.nn.functional.softplus
                layers = [NetworkLayer(self.f_biases[0].numpy().copy(), None, self.f_input[0].numpy() / sv)]
                layers += [NetworkLayer(b.numpy().copy(), softplus(raw).numpy().copy(), U.numpy() / sv)
                           for raw, U, b in zip(self.f_hidden_raw, self.f_input[1:], self.f_biases[1:])]
                f_network = ScalarNetwork(layers, self.cF * softplus(self.f_output_raw).numpy(), "softplus")
            linear = {e["name"]: X.numpy().copy() for e, X in zip(self.linear, self.linear_matrices())}
        return mass, linear, polynomial, u_network, powers, f_network


def train(module: SpMLModule, train_arrays, validation_arrays, config, progress) -> dict:
    r"""Minimise ``||R||_F^2 / ||Y||_F^2`` (+ weight decay) over the module's weights by full-batch L-BFGS.

    ``train_arrays``/``validation_arrays``: ``(q, v, a, Y, blocks, ||Y||_F^2)`` with (K, r) arrays
    and a list of (K, p_j) blocks (:meth:`SpMLModule.residual`).
    Every ``check_every`` iterations the loss on the validation trajectory (the training
    data without one) is compared with the best so far: the best weights are kept, and
    training stops after ``patience`` checks without a relative improvement of ``tolerance``.
    Returns the history and the best check. Runs on ``config.threads`` torch threads (restored
    after): at these sizes intra-op threads cost more than they give (measured on 2 shared
    cores: a (9000, 3) x (3, 16) product took 26 ms on 2 threads, 0.36 ms on 1).
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(int(config.threads))
    try:
        return _train(module, train_arrays, validation_arrays, config, progress)
    finally:
        torch.set_num_threads(threads)


def _train(module, train_arrays, validation_arrays, config, progress) -> dict:
    tensors = []
    for arrays in (train_arrays, validation_arrays):
        if arrays is not None:
            q = _tensor(arrays[0])
            tensors.append((q, *(_tensor(x) for x in arrays[1:4]), [_tensor(D) for D in arrays[4]],
                            module.features(q), float(arrays[5])))
    train_t = tensors[0]
    valid_t = tensors[1] if validation_arrays is not None else None
    parameters = [p for p in module.parameters() if p.requires_grad]

    def lbfgs():
        return torch.optim.LBFGS(parameters, lr=1.0, max_iter=config.check_every,
                                 history_size=config.history_size, line_search_fn="strong_wolfe",
                                 tolerance_grad=1e-14, tolerance_change=1e-16)

    optimizer = lbfgs()
    decay = [p for name, p in module.named_parameters() if "weights" in name or "input" in name or "raw" in name]

    def loss_of(arrays):
        q, v, a, Y, blocks, features, norm = arrays
        R = module.residual(q, v, a, Y, blocks, features)
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
        return float(loss_of(arrays).detach())

    history, best = [], {"loss": np.inf, "iteration": 0, "state": None}
    stale, iterations, offset, stalled = 0, 0, 0, False
    while iterations < config.max_iterations:
        optimizer.step(closure)
        done = offset + int(optimizer.state[parameters[0]].get("n_iter", 0))
        step_iterations = max(done - iterations, 1)
        iterations = done
        train_loss, check = float(loss_of(train_t).detach()), score()
        history.append({"iteration": iterations, "loss": train_loss, "validation_loss": check})
        progress.label = f"SpML fit: loss {train_loss:.3e}" + (f", validation {check:.3e}" if valid_t else "")
        progress.update(step_iterations)
        if not np.isfinite(check):
            break
        if check < best["loss"] * (1.0 - config.tolerance):
            best = {"loss": check, "iteration": iterations,
                    "state": {k: v.detach().clone() for k, v in module.state_dict().items()}}
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
            stalled, offset, optimizer = True, iterations, lbfgs()
        else:
            stalled = False
    if best["state"] is not None:
        module.load_state_dict(best["state"])
    return {"history": history, "best_iteration": best["iteration"], "best_loss": best["loss"],
            "iterations": iterations}
