"""The benchmark's MuJoCo flex comparison runs and measures what it says."""

from hybrid import rigid
from hybrid.mesh import uv_sphere


def test_flex_sphere_loses_volume_under_load():
    # MuJoCo's 2D flex has no volume constraint: a soft 4 kg shell resting on a
    # plane flattens, so its enclosed volume drops measurably within 0.3 s
    mesh = uv_sphere(0.12)
    row = rigid.flex_sphere_run(mesh.vert_pos, mesh.face_vert, duration_s=0.3)
    assert row["nvert"] == 80
    assert row["us_per_step"] > 0
    assert row["volume_change"] < -0.01
