"""The demo generator removes only what it wrote: it never loses a user's data."""

import pytest

from irdic.errors import ConfigError
from irdic.synthetic.demo_folder import make_demo


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "demo"
    make_demo(out, scale="tiny")
    return out


def test_dot_entries_are_a_users_data(tmp_path):
    home = tmp_path / "home"
    (home / ".ssh").mkdir(parents=True)
    (home / ".ssh" / "id_ed25519").write_text("key")
    (home / ".git").mkdir()
    (home / ".git" / "HEAD").write_text("ref: refs/heads/main")
    (home / ".bashrc").write_text("alias ll='ls -l'")
    with pytest.raises(ConfigError, match=r"home: folder exists and holds \.bashrc, \.git, \.ssh, which the demo "
                                          r"did not write"):
        make_demo(home, scale="tiny")
    assert (home / ".ssh" / "id_ed25519").read_text() == "key"
    assert (home / ".git" / "HEAD").exists() and (home / ".bashrc").exists()
    assert sorted(p.name for p in home.iterdir()) == [".bashrc", ".git", ".ssh"]


def test_arguments_are_checked_before_anything_is_removed(demo):
    before = sorted(p.relative_to(demo) for p in demo.rglob("*"))
    for kwargs, msg in (({"scale": "huge"}, "scale"), ({"ir_noise": -1.0}, "ir_noise"),
                        ({"dic_noise": float("nan")}, "dic_noise"), ({"seed": -3}, "seed")):
        with pytest.raises(ConfigError, match=msg):
            make_demo(demo, **{"scale": "tiny", **kwargs})
    assert sorted(p.relative_to(demo) for p in demo.rglob("*")) == before


def test_a_file_added_to_the_demo_folder_is_kept(demo):
    note = demo / "tube" / "my_notes.txt"
    note.write_text("precious")
    try:
        with pytest.raises(ConfigError, match="holds tube, which the demo did not write"):
            make_demo(demo, scale="tiny")
        assert note.read_text() == "precious"
        assert (demo / "manifest.yaml").exists()
    finally:
        note.unlink()


def test_symlinked_outdir_is_refused(demo, tmp_path):
    link = tmp_path / "link"
    link.symlink_to(demo, target_is_directory=True)
    with pytest.raises(ConfigError, match=r"link: the demo folder is a symbolic link"):
        make_demo(link, scale="tiny")
    assert (demo / "manifest.yaml").exists()


def test_rerun_replaces_its_own_files_also_without_the_manifest(demo):
    # Snakemake deletes the manifest (the rule's output) before it runs the rule again
    (demo / "manifest.yaml").unlink()
    make_demo(demo, scale="tiny", seed=1)
    assert "seed: 1" in (demo / "manifest.yaml").read_text()
    assert (demo / "tube" / "truth.zarr").is_dir() and (demo / "setup" / "markers.txt").is_file()
