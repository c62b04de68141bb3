"""raf bench planning's leg set and figures (the CPU figures themselves are the benchmark's, not a test's)."""
import argparse

from robotatfactory.bench import planning
from robotatfactory.bench import registry


def _args(*agent):
    p = argparse.ArgumentParser()
    planning.add_arguments(p)
    return p.parse_args(["--repeats", "1"] + [a for s in agent for a in ("--agent", s)])


def test_the_leg_set_picks_where_parts_are_taken_and_places_where_they_go(field):
    todo = planning.legs_to_plan(field)
    kinds = {(ref.zone, field.slot(ref.zone, ref.number).role, carrying, dock) for _, ref, carrying, dock in todo}
    assert kinds == {("incoming", "store", False, "pick"), ("outgoing", "store", True, "place"),
                     ("machine_A", "input", True, "place"), ("machine_A", "output", False, "pick"),
                     ("machine_B", "input", True, "place"), ("machine_B", "output", False, "pick")}
    assert len(todo) == 16 * len(planning.POSES) and "planning" in registry()


def test_every_leg_is_planned_and_the_agent_settings_act(field):
    out = planning.run(_args())
    assert out["legs_without_path"] == 0 and out["legs_empty"] == out["legs_carrying"] == 48
    assert out["cpu_ms_per_leg_carrying"] > 0 and 2.0 < out["drive_s_per_leg_empty_mean"] < 10.0
    for r in (1, 3):  # a decision (the choice after a pick) costs more than a cycle that follows a path
        assert out[f"round{r}_cycle_ms_max"] > 3 * out[f"round{r}_cycle_ms_median"] > 0
        assert out[f"round{r}_cycles_over_period"] >= 0
    plain = planning.run(_args("legs.arc_join=0"))
    assert plain["agent_settings"] == "legs.arc_join=0"
    # legs under machine B join their slot's normal on an arc only with arc_join: fewer turns on the spot
    assert plain["drive_s_per_leg_carrying_mean"] > out["drive_s_per_leg_carrying_mean"]
    assert plain["drive_s_per_leg_empty_mean"] == out["drive_s_per_leg_empty_mean"]
