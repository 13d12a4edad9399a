"""The estimators as objects whose settings are constructor parameters (scikit-learn, lmfit).

::

    ident = hystcli.Identifier(level=0.9, use_tip=False).fit(sweep)   # -> Identification
    shift = hystcli.ShiftDetector(step=0.25).detect(ident.model, replay, knob=1)  # -> ShiftResult
    diag = hystcli.Diagnoser(max_effects=2).diagnose(model, runs)     # -> Diagnosis

Each object is a thin holder of settings around one library function (:func:`hystcli.identify`,
:func:`hystcli.detect_shift`, :func:`hystcli.diagnose`): it computes nothing itself. Its
parameters are the fields of :class:`hystcli.settings.Settings` (when the function takes
``settings=``) and the function's own keyword options, with their defaults read from there, so a
default is written once. ``get_params()`` returns exactly the constructor's parameters and
``set_params(**kw)`` takes them back; ``inspect.signature(Identifier)`` shows them.
"""
from __future__ import annotations

import inspect
from dataclasses import fields
from typing import Any, Callable, ClassVar, Sequence

from .core.model import Model
from .core.run import Run
from .diagnosis import Diagnosis, diagnose
from .identification import Identification, identify
from .settings import DEFAULT, Settings
from .shift import ShiftResult
from .shift.search import detect_shift

__all__ = ["Diagnoser", "Estimator", "Identifier", "ShiftDetector"]

_KW = inspect.Parameter.KEYWORD_ONLY


class Estimator:
    """Base of the estimator objects: parameters in, one library function called with them.

    A subclass names its function and the function's arguments that are data rather than
    settings (``data=``, given to the method that runs it); every other keyword of the function
    becomes a constructor parameter, and so does every :class:`Settings` field when the function
    takes ``settings=``.
    """

    _function: ClassVar[Callable[..., Any]]
    _settings_names: ClassVar[tuple[str, ...]] = ()
    _option_names: ClassVar[tuple[str, ...]] = ()
    __signature__: ClassVar[inspect.Signature]

    def __init_subclass__(cls, function: Callable[..., Any], data: Sequence[str] = (), **kw: Any) -> None:
        super().__init_subclass__(**kw)
        sig = inspect.signature(function)
        params = []
        if "settings" in sig.parameters:
            params += [inspect.Parameter(f.name, _KW, default=getattr(DEFAULT, f.name), annotation=f.type)
                       for f in fields(Settings)]
        # a function's shortcut for a Settings field (detect_shift's false_alarm=) is that field
        taken = {p.name for p in params}
        options = [p.replace(kind=_KW) for name, p in sig.parameters.items()
                   if name not in data and name != "settings" and name not in taken]
        cls._function = staticmethod(function)  # type: ignore[assignment]
        cls._settings_names = tuple(p.name for p in params)
        cls._option_names = tuple(p.name for p in options)
        # what help(), IDEs and inspect show for the class: the real parameters, not **params
        cls.__signature__ = inspect.Signature(params + options)

    def __init__(self, **params: Any) -> None:
        self._params = {p.name: p.default for p in self.__signature__.parameters.values()}
        self.set_params(**params)

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor's parameters and their values (scikit-learn's ``get_params``).

        Parameters
        ----------
        deep : bool
            Accepted for scikit-learn's signature; no parameter is itself an estimator.

        Returns
        -------
        dict of str to object
            Exactly the names ``__init__`` takes; ``type(self)(**est.get_params())`` is an equal
            estimator.
        """
        return dict(self._params)

    def set_params(self, **params: Any) -> "Estimator":
        """Change parameters in place and return the estimator (scikit-learn's ``set_params``).

        Raises
        ------
        TypeError
            A name that is not a parameter (the message lists the ones there are).
        HystError
            A value :class:`Settings` refuses (e.g. ``level`` outside [0.5, 1)); the estimator is
            left unchanged.
        """
        unknown = sorted(set(params) - set(self._params))
        if unknown:
            raise TypeError(f"{type(self).__name__} has no parameter {', '.join(map(repr, unknown))}; "
                            f"its parameters are {', '.join(self._params)}")
        new = {**self._params, **params}
        self._settings_of(new)  # validate now, not at the first fit
        self._params = new
        return self

    @property
    def settings(self) -> Settings:
        """The :class:`Settings` these parameters make (the defaults for any not given)."""
        return self._settings_of(self._params)

    def _settings_of(self, params: dict[str, Any]) -> Settings:
        return Settings(**{n: params[n] for n in self._settings_names})

    def _call(self, *args: Any, **data: Any) -> Any:
        """The library function, with these parameters and the data."""
        options = {n: self._params[n] for n in self._option_names}
        if self._settings_names:
            options["settings"] = self.settings
        return type(self)._function(*args, **options, **data)

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and other.get_params() == self.get_params()  # type: ignore[attr-defined]

    __hash__ = None  # type: ignore[assignment]  # mutable through set_params

    def __repr__(self) -> str:
        # like scikit-learn: only what differs from the defaults
        changed = [f"{n}={v!r}" for n, v in self._params.items()
                   if v != self.__signature__.parameters[n].default]
        return f"{type(self).__name__}({', '.join(changed)})"


class Identifier(Estimator, function=identify, data=("run",)):
    """Identification of the straight-shaft model as an object: :func:`hystcli.identify`'s settings.

    Parameters
    ----------
    **params
        Every :class:`hystcli.settings.Settings` field (``level``, ``loss``, ``filter_hz``,
        ``current_sign``, ...) and :func:`hystcli.identify`'s options ``knobs``, ``omega`` and
        ``use_tip``, with the same defaults; ``inspect.signature(Identifier)`` lists them.

    Examples
    --------
    >>> import hystcli
    >>> est = hystcli.Identifier(level=0.9, use_tip=False)
    >>> est.get_params()["level"], est.settings.level
    (0.9, 0.9)
    >>> est.set_params(level=0.95)
    Identifier(use_tip=False)
    """

    def fit(self, run: Run) -> Identification:
        """Identify the model of each knob from a sweep (:func:`hystcli.identify`).

        Parameters
        ----------
        run : Run
            The sweep: ``t``, ``q<k>``, and ``y<k>`` and/or ``c<k>`` per knob.

        Returns
        -------
        Identification
        """
        return self._call(run)


class ShiftDetector(Estimator, function=detect_shift, data=("model", "probe", "knob", "progress")):
    """Algorithm 1 as an object: :func:`hystcli.detect_shift`'s settings.

    Parameters
    ----------
    **params
        Every :class:`hystcli.settings.Settings` field (``level``, ``false_alarm``,
        ``max_offset_halfwidth``, ...) and :func:`hystcli.detect_shift`'s options ``eps_upper``,
        ``step``, ``max_steps``, ``max_travel``, ``direction`` and ``return_home``, with the same
        defaults.
    """

    def detect(self, model: Model, probe: Any, knob: int = 1,
               progress: Callable[..., None] | None = None) -> ShiftResult:
        """Find the shift of one knob's dead zone (:func:`hystcli.detect_shift`).

        Parameters
        ----------
        model : Model
            The straight-shaft model, with the identification sweep's reading of the current.
        probe : Probe or Run
            A recorded replay or a live probe.
        knob : int
        progress : callable, optional
            Called with each probe sample and the slope of the last readings.

        Returns
        -------
        ShiftResult
        """
        return self._call(model, probe, knob=knob, progress=progress)


class Diagnoser(Estimator, function=diagnose, data=("model", "runs", "progress", "sweep")):
    """The diagnosis as an object: :func:`hystcli.diagnose`'s settings.

    Parameters
    ----------
    **params
        :func:`hystcli.diagnose`'s options ``holdout``, ``candidates``, ``max_effects``,
        ``bootstrap`` and ``seed``, with the same defaults (the diagnosis takes no
        :class:`Settings`).
    """

    def diagnose(self, model: Model, runs: Sequence[Run], sweep: Run | None = None,
                 progress: Callable[[str], None] | None = None) -> Diagnosis:
        """Where the model departs from the runs, which effect causes it, how far adding it helps.

        Parameters
        ----------
        model : Model
        runs : sequence of Run
        sweep : Run, optional
            The model's identification sweep (re-identifies the loop under a time-dependent effect).
        progress : callable, optional

        Returns
        -------
        Diagnosis
        """
        return self._call(model, runs, sweep=sweep, progress=progress)
