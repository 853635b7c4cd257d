r"""The eigensystem realisation algorithm (ERA): a balanced first-order model from Markov parameters."""

from __future__ import annotations

from femrom._errors import FemromTypeError, positive_integer
from femrom.inference._io_data import InputOutputData, MarkovParameters
from femrom.inference._learner import Learner, refuse_validation, register_learner
from femrom.inference._realization import era_realization


@register_learner("era")
class ERA(Learner):
    r"""ERA (Juang & Pappa, J. Guid. Control Dyn. 8(5), 1985) on given Markov parameters.

    ``H_0 = [Y_{i+j+1}]`` and ``H_1 = [Y_{i+j+2}]`` (``a`` block rows, ``b`` block
    columns, (a p, b m)), ``H_0 ~ P_n S_n Q_n^T``,

    .. math::

        A = S_n^{-1/2} P_n^\top H_1 Q_n S_n^{-1/2}, \quad B = S_n^{1/2} Q_n^\top E_m, \quad
        C = E_p^\top P_n S_n^{1/2}, \quad D = Y_0

    (:func:`~femrom.inference.era_realization`). The Markov parameters come from
    an impulse response (:func:`~femrom.inference.system_impulse_response` of
    the full-order system, :func:`~femrom.inference.impulse_response` of any
    stepper, :func:`~femrom.inference.markov_parameters` of a model) or from
    input-output data (:func:`~femrom.inference.okid_markov_parameters`; the
    :class:`OKID` learner does both steps). The model is not stabilised:
    ``describe()`` reports the spectral radius.

    Parameters
    ----------
    order : int
        ``n``.
    rows, columns : int, optional
        Block rows ``a`` and columns ``b`` (default: the given ``Y_1 ... Y_{N-1}``
        split evenly); needs ``N >= a + b + 1``.
    output_directions, input_directions : int, optional
        Tangential reduction of the channels before the Hankel matrix is formed.

    Attributes
    ----------
    operators_ : StateSpaceOperators
    hankel_singular_values_ : list of float
        The leading singular values of ``H_0`` (``order + 10``).
    markov_error_ : float
        Relative error of the model's ``Y_0 ... Y_{a+b}`` against the given ones.
    """

    method = "era"
    model = "state_space"

    def __init__(self, order: int, *, rows: int | None = None, columns: int | None = None,
                 output_directions: int | None = None, input_directions: int | None = None):
        self.order = positive_integer(order, "order")
        self.rows, self.columns = (positive_integer(v, n, optional=True) for v, n in ((rows, "rows"), (columns, "columns")))
        self.output_directions, self.input_directions = (positive_integer(v, n, optional=True) for v, n in (
            (output_directions, "output_directions"), (input_directions, "input_directions")))
        self.operators_ = None

    needs = ("markov",)

    @classmethod
    def for_training(cls, training, r: int, **options):
        """ERA of order ``2 r`` on the study's Markov parameters."""
        options.setdefault("order", 2 * r)
        return cls(**options), training.require_markov("ERA"), None

    def fit(self, data: MarkovParameters, *, validation=None) -> "ERA":
        """Realise the Markov parameters ``data`` (:class:`~femrom.inference.MarkovParameters`; no validation data)."""
        refuse_validation(self, validation)
        if isinstance(data, InputOutputData):
            raise FemromTypeError("ERA realises Markov parameters; for input-output data use OKID, "
                                  "or ERA on okid_markov_parameters(data, observer_order, count)")
        if not isinstance(data, MarkovParameters):
            raise FemromTypeError(f"ERA.fit takes MarkovParameters, got {type(data).__name__}")
        ops = era_realization(data, self.order, rows=self.rows, columns=self.columns,
                              output_directions=self.output_directions, input_directions=self.input_directions)
        used = ops.metadata["rows"] + ops.metadata["columns"] + 1
        self.markov_error_ = ops.markov_parameters(used).relative_error(data, used)
        self.hankel_singular_values_ = ops.metadata["hankel_singular_values"]
        ops.metadata.update(markov_source=data.metadata.get("source"), markov_error=self.markov_error_)
        self.operators_ = ops
        return self

    def describe(self) -> dict:
        out = {"method": self.method, "order": self.order, "rows": self.rows, "columns": self.columns,
               "output_directions": self.output_directions, "input_directions": self.input_directions}
        if self.is_fitted:
            meta = self.operators_.metadata
            out.update(rows=meta["rows"], columns=meta["columns"], hankel_shape=meta["hankel_shape"],
                       spectral_radius=self.operators_.spectral_radius, markov_error=self.markov_error_,
                       hankel_singular_values=self.hankel_singular_values_[:self.order + 1],
                       svd_seconds=meta["svd_seconds"])
        return out
