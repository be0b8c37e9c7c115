"""The method hint: the faster method by the measured crossover (emu.solve.advice),
printed by `emu solve`, `emu run` and the demo (tests/test_cli.py)."""
from __future__ import annotations

import emu
from emu.solve import advice


def test_the_hint_names_the_faster_method_by_soft_tets(monkeypatch):
    s = emu.scenes.arm(1)
    soft = sum(len(p.tets) for p in s.parts.values() if p.kind != "bone")
    assert advice.soft_tets(s) == soft < len(s.tets)          # bone tets do not count
    assert advice.faster_method(s) == "fem" and advice.method_hint(s, "fem") is None
    hint = advice.method_hint(s, "emu", sequence=True)
    assert "FEM is as fast" in hint and "frames of a sequence" in hint and f"{soft:,} soft tets" in hint
    assert "with a moving bone" in hint                               # the arm's forearm moves
    monkeypatch.setitem(advice.EMU_FROM_SOFT_TETS, ("bones", "single"), soft)   # the crossover at this size
    assert advice.faster_method(s) == "emu" and advice.method_hint(s, "emu") is None
    assert "EMU is faster" in advice.method_hint(s, "fem")
    assert advice.method_hint(s, "fem", sequence=True) is None      # the sequence crossover is apart
    assert "slower at every size measured" in advice.method_hint(s, "emu", sequence=True)
    fusiform = emu.scenes.fusiform(1, warn=False)                     # no bone: the other crossover
    assert advice.faster_method(fusiform) == "fem" and "without moving bones" in advice.method_hint(fusiform, "emu")
    # a sequence without moving bones: EMU measured faster per warm frame from 81k soft tets
    hint = advice.method_hint(fusiform, "emu", sequence=True)
    assert "FEM is as fast" in hint and "measured crossover" in hint and "81,000 soft tets" in hint


def test_run_logs_the_hint(tmp_path):
    from test_scenefile import GOOD, write
    from emu.app.run import run_scene
    from emu.app.scenefile import load_scene_file

    lines = []
    log = run_scene(load_scene_file(write(tmp_path, GOOD)), str(tmp_path / "out"), progress=lines.append)
    assert log["method_hint"] is not None and log["method_hint"] in lines
