"""Where a rigid model comes from (hybrid.rigid.mjcf): the trunk's MJCF and its named parts,
load errors that name the file, and MuJoCo's warnings sent to the log."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from helpers import RIBS

from hybrid import rigid
from hybrid.errors import RigidError


def test_trunk_model_compiles_with_named_parts():
    m = rigid.load_spec(rigid.TRUNK_XML).compile()
    bodies = {m.body(i).name for i in range(m.nbody)}
    sites = {m.site(i).name for i in range(m.nsite)}
    assert {"spine", "rib_left", "rib_right"} <= bodies
    assert {"rib_left_attach", "rib_right_attach", "spine_base"} <= sites
    assert m.tendon("sternum").id == 0 and m.tendon_stiffness[0] > 0
    for rib in RIBS:
        j = m.joint(f"{rib}_hinge")
        assert j.type[0] == mujoco.mjtJoint.mjJNT_HINGE
        assert j.stiffness[0] == pytest.approx(12.0)
        assert m.body_mass[m.body(rib).id] == pytest.approx(0.2)
    assert m.opt.timestep == pytest.approx(1e-3)
    assert m.body_jntnum[m.body("spine").id] == 0  # fixed to the world


def test_load_spec_errors_name_the_file():
    with pytest.raises(RigidError, match="nope.xml.*no such file"):
        rigid.load_spec("/nonexistent/nope.xml")
    with pytest.raises(RigidError, match="MuJoCo cannot parse it.*bogus"):
        rigid.load_spec('<mujoco><worldbody><geom type="bogus"/></worldbody></mujoco>')
    with pytest.raises(RigidError, match="unknown site name"):
        rigid.RigidSystem(rigid.load_spec(rigid.TRUNK_XML), ["no_such_site"])
    with pytest.raises(RigidError, match="timestep"):
        rigid.RigidSystem(rigid.load_spec(rigid.TRUNK_XML), timestep=-1.0)


def test_mujoco_warnings_go_to_the_log_not_to_a_file_in_the_working_folder(tmp_path, monkeypatch, caplog):
    """MuJoCo's own handler appends to MUJOCO_LOG.TXT in the working folder; hybrid
    routes its warnings to the logger "hybrid.mujoco"."""
    import logging

    import mujoco

    from hybrid import rigid

    monkeypatch.chdir(tmp_path)
    model = mujoco.MjModel.from_xml_path(str(rigid.TRUNK_XML))
    data = mujoco.MjData(model)
    data.qpos[0] = np.nan  # MuJoCo resets the state and warns
    with caplog.at_level(logging.WARNING, logger="hybrid.mujoco"):
        mujoco.mj_step(model, data)
    assert any("MuJoCo: Nan, Inf or huge value in QPOS" in r.getMessage() for r in caplog.records)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
