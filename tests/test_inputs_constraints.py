"""Point constraints that cannot both hold on one point are refused at compile."""

import pytest

from hybrid.errors import SceneError
from hybrid.model import compile_scene
from hybrid.regions import HalfSpace, Indices
from hybrid.scene import KeepIn, Masses, Nailed, Prescribed, Scene, Volume

TOP = HalfSpace((0.0, 0.0, 0.08), (0.0, 0.0, 1.0))  # the 14 points of the top cap of the 80-point sphere


def _nailed(region=TOP):
    return Nailed(region=region, name="spine")


def _prescribed(name="lift", region=TOP):
    return Prescribed(region=region, displacement_m=(0.0, 0.0, 0.05), name=name)


def _keep_in(name="table", region=TOP):
    return KeepIn(region=region, shape="half_space", point_m=(0.0, 0.0, -0.05), normal=(0.0, 0.0, 1.0), name=name)


@pytest.mark.parametrize(
    "first, second, said",
    [
        (_nailed(), _prescribed(), "nailed"),
        (_nailed(), _keep_in(), "nailed"),
        (_prescribed(), _keep_in(), "prescribed"),
        (_keep_in(), _nailed(), "kept in a region"),
        (_prescribed("a"), _prescribed("b"), "prescribed"),
    ],
    ids=["nailed+prescribed", "nailed+keep_in", "prescribed+keep_in", "keep_in+nailed", "prescribed+prescribed"],
)
def test_two_point_constraints_that_cannot_both_hold_are_refused(first, second, said):
    """Item 4: the points of the top cap both nailed and prescribed (they moved
    50 mm), nailed and kept in a region (74.8 mm), ... : one line naming a few
    of the points, their count and both constraints."""
    scene = Scene(formulation="paper", masses=Masses(total_kg=1.0), constraints=(first, second, Volume()))
    with pytest.raises(SceneError) as err:
        compile_scene(scene)
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith(f"constraints[{second.name!r}]: ")
    assert f"points are also {said} by constraints[{first.name!r}]: vertices " in message
    assert "not both" in message


def test_the_message_counts_the_points_and_lists_a_few():
    """Item 4: 14 shared points, the first five listed and the rest counted."""
    with pytest.raises(SceneError) as err:
        compile_scene(Scene(formulation="paper", constraints=(_nailed(), _prescribed())))
    message = str(err.value)
    assert "14 points are also nailed by constraints['spine']: vertices 0, 1, 2, 3, 4 and 9 more;" in message


def test_constraints_that_agree_or_do_not_share_points_compile():
    """Item 4: two nails on one point agree, two keep-in regions may overlap, and
    a nail beside a prescribed point on other points is fine."""
    compile_scene(Scene(formulation="paper", constraints=(_nailed(), Nailed(region=Indices([0, 1]), name="more"))))
    compile_scene(Scene(formulation="paper", constraints=(_keep_in("a"), _keep_in("b"))))
    compile_scene(
        Scene(
            formulation="paper", constraints=(Nailed(region=Indices([0]), name="n"), _prescribed(region=Indices([1])))
        )
    )


def test_a_linked_point_kept_in_a_region_is_refused_by_the_same_check():
    """Item 4: linked and kept in a region joins linked and nailed, refused with
    the same line before MuJoCo compiles."""
    pytest.importorskip("mujoco")
    from hybrid.scene import Rigid, RigidLink

    scene = Scene(
        formulation="paper",
        masses=Masses(total_kg=4.0),
        constraints=(_keep_in(),),
        rigid=Rigid(mjcf="trunk", links=(RigidLink(TOP, "rib_left"),)),
    )
    with pytest.raises(SceneError) as err:
        compile_scene(scene)
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("constraints['table'].region: ")
    assert "points are also linked to a rigid body by rigid.links: vertices" in message
