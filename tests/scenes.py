"""The simulated device of probes placed by hand, for the tests: a scene without a scene file."""

from mows.physics.fluxgate import NoiseModel
from mows.sim.scenario import Scenario
from mows.sim.sections import Environment, Integrator, SceneProbe
from mows.sim.simulator import SimulatedDevice


def scene_device(placed, sources=(), sample_rate_hz=10_000.0, substeps=2) -> SimulatedDevice:
    """The noiseless simulated device of the probes ``placed`` (PlacedProbe) in the field of
    ``sources``, sampled at ``sample_rate_hz`` with ``substeps`` RK4 steps per sample."""
    scene = tuple(SceneProbe(p.probe, p.pose) for p in placed)
    return SimulatedDevice(
        Scenario(
            probes=scene,
            environment=Environment(tuple(sources)),
            sample_rate_hz=sample_rate_hz,
            integrator=Integrator(substeps=substeps),
            noise=NoiseModel(),
        )
    )
