import numpy as np
import open3d as o3d
import pytest

from optrack.io.pcd import PCDError, read_pcd, write_pcd


def test_five_people_reads_as_an_organised_cloud_with_colour(shared_data):
    cloud = read_pcd(shared_data / "pcl" / "five_people.pcd")
    assert cloud.organized and (cloud.height, cloud.width) == (480, 640)
    assert cloud.points.shape == (480, 640, 3) and cloud.points.dtype == np.float32
    assert cloud.colors.shape == (480, 640, 3) and cloud.colors.dtype == np.uint8
    assert cloud.data == "binary_compressed" and "rgba" in cloud.fields
    valid = np.isfinite(cloud.points[..., 2])
    assert 0.5 * valid.size < valid.sum() < valid.size  # a real Kinect frame has holes
    z = cloud.points[..., 2][valid]
    assert 0.4 < np.median(z) < 8.0  # metres, in front of the camera
    assert cloud.colors[valid].std() > 10  # real colours, not a constant
    # Organised: pixel (v, u) looks along x/z = (u - cx)/fx with PCL's Kinect intrinsics.
    v, u = np.nonzero(valid)
    p = cloud.points[v, u]
    np.testing.assert_allclose(p[:, 0] / p[:, 2], (u - 319.5) / 525, atol=2e-3)
    np.testing.assert_allclose(p[:, 1] / p[:, 2], (v - 239.5) / 525, atol=2e-3)


def test_office_frame_reads_too(shared_data):
    cloud = read_pcd(shared_data / "pcl" / "office1.pcd")
    assert cloud.points.shape[:2] == (cloud.height, cloud.width)
    assert len(cloud.valid_points()) > 1000


@pytest.mark.parametrize(
    ("ascii", "compressed", "data"),
    [(True, False, "ascii"), (False, False, "binary"), (False, True, "binary_compressed")],
)
def test_every_pcd_encoding_reads_back(tmp_path, ascii, compressed, data):
    rng = np.random.default_rng(1)
    points = rng.uniform(-2, 2, (500, 3))
    colors = rng.uniform(0, 1, (500, 3))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.colors = o3d.utility.Vector3dVector(colors)
    path = tmp_path / f"{data}.pcd"
    assert o3d.io.write_point_cloud(str(path), cloud, write_ascii=ascii, compressed=compressed)
    read = read_pcd(path)
    assert read.data == data and not read.organized
    np.testing.assert_allclose(read.points, points, atol=1e-5)
    np.testing.assert_allclose(read.colors, np.rint(colors * 255), atol=1)


def test_organised_cloud_with_holes_round_trips(tmp_path):
    rng = np.random.default_rng(2)
    points = rng.uniform(0, 3, (48, 64, 3)).astype(np.float32)
    points[rng.random((48, 64)) < 0.2] = np.nan
    colors = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
    write_pcd(tmp_path / "c.pcd", points, colors)
    read = read_pcd(tmp_path / "c.pcd")
    assert read.organized and (read.height, read.width) == (48, 64)
    np.testing.assert_array_equal(read.points, points)
    valid = np.isfinite(points[..., 0])
    np.testing.assert_array_equal(read.colors[valid], colors[valid])
    write_pcd(tmp_path / "xyz.pcd", points.reshape(-1, 3))
    assert read_pcd(tmp_path / "xyz.pcd").colors is None


def test_truncated_or_foreign_files_get_one_sentence(tmp_path, shared_data):
    whole = (shared_data / "pcl" / "five_people.pcd").read_bytes()
    (tmp_path / "cut.pcd").write_bytes(whole[: len(whole) // 2])
    with pytest.raises(PCDError, match="damaged"):
        read_pcd(tmp_path / "cut.pcd")
    (tmp_path / "notes.pcd").write_text("hello\n")
    with pytest.raises(PCDError, match="not a PCD file"):
        read_pcd(tmp_path / "notes.pcd")
    with pytest.raises(PCDError, match="does not exist"):
        read_pcd(tmp_path / "missing.pcd")


@pytest.mark.parametrize("data", ["binary", "ascii", "binary_compressed"])
def test_a_header_promising_more_points_than_the_file_holds_is_refused_before_reading(
    tmp_path, data
):
    """A header of 200000x200000 points over 1 kB of data: one sentence, nothing allocated
    (Open3D would allocate what the header says)."""
    header = (
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH 200000\nHEIGHT 200000\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 40000000000\nDATA {data}\n"
    )
    body = np.uint32([1000, 4_000_000]).tobytes() if data == "binary_compressed" else b""
    path = tmp_path / "lie.pcd"
    path.write_bytes(header.encode() + body + b"\0" * 1000)
    with pytest.raises(PCDError, match=r"promises 40000000000 points .* too few for them"):
        read_pcd(path)


def test_a_compressed_cloud_claiming_more_than_lzf_can_hold_is_refused(tmp_path):
    """PCL's sizes agree (1e6 points of 12 bytes) but 1 kB of LZF cannot unpack to 12 MB."""
    header = (
        "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1000000\nHEIGHT 1\nDATA binary_compressed\n"
    )
    path = tmp_path / "lzf.pcd"
    path.write_bytes(header.encode() + np.uint32([1000, 12_000_000]).tobytes() + b"\0" * 1000)
    with pytest.raises(PCDError, match="damaged"):
        read_pcd(path)


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("WIDTH -5", "malformed WIDTH/HEIGHT"),
        ("SIZE 4 4", "malformed SIZE/COUNT"),
        ("VIEWPOINT 0 0 0 one 0 0 0", "malformed VIEWPOINT '0 0 0 one 0 0 0'"),
        ("VIEWPOINT 0 0 nan 1 0 0 0", "seven finite numbers"),
    ],
)
def test_malformed_header_numbers_get_one_sentence(tmp_path, line, message):
    lines = {"FIELDS": "x y z", "SIZE": "4 4 4", "TYPE": "F F F", "WIDTH": "3", "HEIGHT": "1"}
    key, _, value = line.partition(" ")
    lines[key] = value
    text = "".join(f"{k} {v}\n" for k, v in lines.items()) + "DATA binary\n"
    path = tmp_path / "bad.pcd"
    path.write_bytes(text.encode() + b"\0" * 36)
    with pytest.raises(PCDError, match=message):
        read_pcd(path)
