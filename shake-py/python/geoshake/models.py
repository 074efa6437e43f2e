"""Compiled systems: the Rust models, with derivatives generated at compile
time by ``constrained_system!`` (no interpretation), parameters by name.

    >>> import geoshake
    >>> geoshake.models.Pendulum(length=1.0, gravity=9.81).dof
    2
"""

from ._geoshake import model as _model, model_names as _model_names

__all__ = []


def _factory(name, params):
    def make(**parameters):
        return _model(name, **parameters)

    make.__name__ = name
    make.__qualname__ = name
    make.__doc__ = (
        f"The compiled model {name}; parameters (by name): {', '.join(params)}."
    )
    return make


for _name, _params in _model_names():
    globals()[_name] = _factory(_name, _params)
    __all__.append(_name)
