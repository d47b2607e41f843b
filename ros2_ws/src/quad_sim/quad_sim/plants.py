"""Which plant a simulator flies: our model of the paper's eq. (1) (``quad_sim``) or RotorPy's ``Multirotor``
(``rotorpy``, or RotorPy's batched twin of it, ``rotorpy-batched``). All have ``step(t, state, forces, dt, air_velocity)``, ``params``, ``disturbances`` and
``with_vehicle(params)``, so :class:`~quad_sim.simulator.Simulator` and everything above it are the same."""
from __future__ import annotations

from quad_msgs_bridge.vehicle_params import Disturbances, ParameterError, VehicleParams

from .model import QuadrotorModel

#: the plant names of --plant, the campaign key plant and the node parameter: our model; RotorPy with its
#: aerodynamics and motor model; RotorPy's rigid body and rotors alone (aero off, instant motors), to compare with
#: ours; RotorPy's BatchedMultirotor (torch) with its aerodynamics and motor model, a whole batch per step (campaigns)
PLANTS = ('quad_sim', 'rotorpy', 'rotorpy-bare', 'rotorpy-batched')
DEFAULT_PLANT = 'quad_sim'


def check_plant(name: str, argument: str = 'plant') -> str:
    """``name`` if it is one of PLANTS, else ParameterError naming ``argument`` and the valid names."""
    if name not in PLANTS:
        raise ParameterError(f'{argument}: {name!r} is not a plant; valid: {", ".join(PLANTS)}')
    return name


def make_plant(name: str, params: VehicleParams, disturbances: Disturbances):
    """The plant ``name`` flying the true vehicle ``params`` (one vehicle or a batch) under ``disturbances``.

    ``rotorpy``: RotorPy with its aerodynamics and its motor model on (:class:`~quad_sim.rotorpy_plant.RotorPyPlant`
    defaults); ``rotorpy-bare``: with both off; ``rotorpy-batched``: the same model as ``rotorpy`` stepped as one
    batch by RotorPy's torch twin (:class:`~quad_sim.rotorpy_batched_plant.BatchedRotorPyPlant`). ParameterError
    if RotorPy (or torch, for the batched one) is not installed or cannot represent the vehicle."""
    if check_plant(name) == 'quad_sim':
        return QuadrotorModel(params, disturbances)
    if name == 'rotorpy-batched':
        from .rotorpy_batched_plant import BatchedRotorPyPlant
        return BatchedRotorPyPlant(params, disturbances)
    from .rotorpy_plant import RotorPyPlant
    if name == 'rotorpy-bare':
        return RotorPyPlant(params, disturbances, aero=False, motor_time_constant_s=0.0)
    return RotorPyPlant(params, disturbances)
