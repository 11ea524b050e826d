"""The exceptions of hybrid (hybrid.errors): one hierarchy under HybridError."""

from __future__ import annotations

from hybrid.errors import ConstraintError, HybridError, MeshError, SceneError, SimulationDiverged


def test_errors_form_a_hierarchy():
    for cls in (MeshError, SceneError, ConstraintError, SimulationDiverged):
        assert issubclass(cls, HybridError)
    assert issubclass(SceneError, ValueError) and issubclass(MeshError, ValueError)


# ---------------------------------------------------------------- every exception pickles
import importlib
import inspect
import pickle
import pkgutil

import numpy as np
import pytest

import hybrid

# a value for each constructor argument an exception class may take, by annotation
_SAMPLES = {
    "str": "a message naming the culprit",
    "float": 0.125,
    "int": 7,
    "Exception": SceneError("forces[0]: expected a term, received 3"),
    "dict": {"summary": {"status": "failed", "duration_s": 0.25}, "trace": np.arange(4.0)},
}


def _package_exceptions() -> list[type]:
    """Every exception class defined in a module of hybrid (private ones too), found
    by importing each module: a new class is tested without being listed here."""
    found = {}
    for info in pkgutil.walk_packages(hybrid.__path__, "hybrid."):
        if info.name == "hybrid.__main__":  # runs the command line when imported
            continue
        module = importlib.import_module(info.name)
        for obj in vars(module).values():
            if inspect.isclass(obj) and issubclass(obj, BaseException) and obj.__module__ == info.name:
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return [found[k] for k in sorted(found)]


def _instance(cls: type) -> BaseException:
    """cls built from sample arguments, with an attribute and a note added later."""
    init = cls.__init__
    if init in (Exception.__init__, BaseException.__init__) or any(
        init is base.__init__ for base in (ValueError, RuntimeError, KeyboardInterrupt, UserWarning)
    ):
        exc = cls(_SAMPLES["str"])
    else:
        args, kwargs = [], {}
        for name, par in list(inspect.signature(init).parameters.items())[1:]:
            if par.kind in (par.VAR_POSITIONAL, par.VAR_KEYWORD) or par.default is not par.empty:
                continue
            annotation = par.annotation if isinstance(par.annotation, str) else getattr(par.annotation, "__name__", "")
            assert annotation in _SAMPLES, f"{cls.__qualname__}({name}: {annotation}): add a sample to _SAMPLES"
            if par.kind == par.KEYWORD_ONLY:
                kwargs[name] = _SAMPLES[annotation]
            else:
                args.append(_SAMPLES[annotation])
        exc = cls(*args, **kwargs)
    exc.seen_at_step = 12
    exc.add_note("while testing")
    return exc


def _same(a, b) -> bool:
    if isinstance(a, BaseException):
        return type(a) is type(b) and a.args == b.args and str(a) == str(b) and _same(vars(a), vars(b))
    if isinstance(a, dict):
        return type(b) is dict and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and np.array_equal(a, b)
    return a == b


def test_package_has_its_exceptions():
    names = {cls.__qualname__ for cls in _package_exceptions()}
    assert {"HybridError", "SimulationDiverged", "RunFailed", "RunInterrupted", "RecordingError"} <= names


@pytest.mark.parametrize("cls", _package_exceptions(), ids=lambda c: f"{c.__module__}.{c.__qualname__}")
def test_every_exception_pickles_to_an_equal_one(cls):
    exc = _instance(cls)
    back = pickle.loads(pickle.dumps(exc))
    assert _same(exc, back), (vars(exc), vars(back))
    assert back.__notes__ == ["while testing"] and back.seen_at_step == 12


def test_diverged_keeps_its_figures_through_pickle():
    exc = SimulationDiverged("diverged at t = 0.5 s", time_s=0.5, step=7, vert=3, dt_suggested_s=1e-4)
    back = pickle.loads(pickle.dumps(exc))
    assert (back.time_s, back.step, back.vert, back.dt_suggested_s) == (0.5, 7, 3, 1e-4)
    assert str(back) == "diverged at t = 0.5 s" and isinstance(back, HybridError)
