"""Short recorded embedded flights for the bag and review tests."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from flight_stack.embedded import FlightResult, fly_embedded
from nnit2fsmc_controller.factory import load_gains
from nnit2fsmc_controller.trajectory import make_scenario
from quad_msgs_bridge.contract import RECORDED_TOPICS
from quad_msgs_bridge.bag.flight_bag import FlightBag, disturbances_label
from quad_msgs_bridge.review.metrics import flight_metrics, has_fuzzy_term
from quad_msgs_bridge.vehicle_params import load_vehicle_file

PARAMS, DISTURBANCES = load_vehicle_file()
SETTLE_TIME = 1.0


class CapturingFlightBag(FlightBag):
    """A FlightBag that also keeps the arguments of every call: what the flight published."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.steps: list[tuple] = []
        self.paths: list = []

    def record_setpoints(self, path) -> None:
        self.paths.append(path)
        super().record_setpoints(path)

    def record_step(self, *values, **named) -> None:
        self.steps.append(values)
        super().record_step(*values, **named)


@dataclass
class RecordedFlight:
    bag: Path
    result: FlightResult
    published: CapturingFlightBag
    metrics: dict = field(default_factory=dict)


def fly_recorded(bag: Path, duration: float = 2.0, controller: str = 'nnit2fsmc', topics=RECORDED_TOPICS,
                 namespace: str = 'quad') -> RecordedFlight:
    """Fly the paper scenario for ``duration`` [s] into the bag at ``bag``; metrics after SETTLE_TIME."""
    with CapturingFlightBag.create(bag, PARAMS, SETTLE_TIME, topics=topics, namespace=namespace,
                                   controller=controller, scenario='paper', backend='embedded', seed=0,
                                   disturbances=disturbances_label(DISTURBANCES.enabled)) as recording:
        result = fly_embedded(controller, make_scenario('paper'), PARAMS, DISTURBANCES, load_gains(), duration,
                              1000.0, bag=recording)
    metrics = flight_metrics(result.record, SETTLE_TIME, PARAMS.F_min, PARAMS.F_max, fuzzy_term=has_fuzzy_term(controller),
                             arm_length=PARAMS.d)
    return RecordedFlight(bag, result, recording, metrics)
