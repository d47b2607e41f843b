"""Which plant a simulator flies: our model of the paper's eq. (1) (``quad_sim``) or RotorPy's ``Multirotor``
(``rotorpy``, or RotorPy's batched twin of it, ``rotorpy-batched``). All have ``step(t, state, forces, dt, air_velocity)``, ``params``, ``disturbances`` and
``with_vehicle(params)``, so :class:`~quad_sim.simulator.Simulator` and everything above it are the same."""
from __future__ import annotations

from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import Disturbances, VehicleParams

from .model import QuadrotorModel

#: the plant names of --plant, the campaign key plant and the node parameter: our model; RotorPy with its
#: aerodynamics and motor model; RotorPy's rigid body and rotors alone (aero off, instant motors), to compare with
#: ours; RotorPy's BatchedMultirotor (torch) with its aerodynamics and motor model, a whole batch per step (campaigns)
PLANT_DESCRIPTIONS = {
    'quad_sim': 'our model of the paper\'s eq. (1), RK4, with section IV disturbances (the default)',
    'rotorpy': 'RotorPy\'s Multirotor with its aerodynamics and motor model (docs/ROTORPY.md)',
    'rotorpy-bare': 'RotorPy\'s rigid body and rotors alone (aero off, instant motors), to compare with ours',
    'rotorpy-batched': 'RotorPy\'s BatchedMultirotor (torch): a campaign batch per step',
    'px4-sitl': 'PX4 SITL\'s own SIH quadrotor over uXRCE-DDS, real time; run_stack.py\'s ROS backend only (docs/PX4.md)',
}
PLANTS = tuple(PLANT_DESCRIPTIONS)
DEFAULT_PLANT = 'quad_sim'
#: not a simulator of ours: PX4 SITL flies it, started with the Agent by flight_stack.px4_sitl (ROS backend only)
PX4_SITL = 'px4-sitl'
#: the controller kind that is PX4's own cascaded controller (run_stack.py --controller px4): flown on PX4_SITL only
PX4_CONTROLLER = 'px4'


def check_plant(name: str, argument: str = 'plant') -> str:
    """``name`` if it is one of PLANTS, else ParameterError naming ``argument`` and the valid names."""
    if name not in PLANTS:
        raise ParameterError(f'{argument}: {name!r} is not a plant; valid: {", ".join(PLANTS)}')
    return name


#: the Python modules each plant needs beyond the stack's own, and where they come from
PLANT_MODULES = {'rotorpy': ('rotorpy',), 'rotorpy-bare': ('rotorpy',), 'rotorpy-batched': ('rotorpy', 'torch')}
PLANT_REQUIREMENTS = {'rotorpy': 'pip install .[rotorpy]', 'rotorpy-bare': 'pip install .[rotorpy]',
                      'rotorpy-batched': 'pip install -r requirements-rotorpy-batched.txt'}


def check_plant_installed(name: str, argument: str = 'plant') -> str:
    """``name`` if the modules its plant needs import, else ParameterError naming the missing one and how to install
    it: checked before anything flies or is written."""
    import importlib.util
    for module in PLANT_MODULES.get(name, ()):
        if importlib.util.find_spec(module) is None:
            raise ParameterError(f'{argument} {name}: needs the Python package {module}, which is not installed for '
                                 f'this interpreter ({PLANT_REQUIREMENTS[name]}; docs/ROTORPY.md)')
    return name


def make_plant(name: str, params: VehicleParams, disturbances: Disturbances):
    """The plant ``name`` flying the true vehicle ``params`` (one vehicle or a batch) under ``disturbances``.

    ``rotorpy``: RotorPy with its aerodynamics and its motor model on (:class:`~quad_sim.rotorpy_plant.RotorPyPlant`
    defaults); ``rotorpy-bare``: with both off; ``rotorpy-batched``: the same model as ``rotorpy`` stepped as one
    batch by RotorPy's torch twin (:class:`~quad_sim.rotorpy_batched_plant.BatchedRotorPyPlant`). ParameterError
    if RotorPy (or torch, for the batched one) is not installed or cannot represent the vehicle."""
    if check_plant(name) == PX4_SITL:
        raise ParameterError(f'plant {PX4_SITL}: PX4 SITL flies it, not a simulator here; fly it with run_stack.py '
                             f'--plant {PX4_SITL} (ROS backend, docs/PX4.md)')
    if name == 'quad_sim':
        return QuadrotorModel(params, disturbances)
    if name == 'rotorpy-batched':
        from .rotorpy_batched_plant import BatchedRotorPyPlant
        return BatchedRotorPyPlant(params, disturbances)
    from .rotorpy_plant import RotorPyPlant
    if name == 'rotorpy-bare':
        return RotorPyPlant(params, disturbances, aero=False, motor_time_constant_s=0.0)
    return RotorPyPlant(params, disturbances)
