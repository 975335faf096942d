"""tools/fetch_assets.py without the network: assets fetched from a tiny git repository made here (``--from-git``)
and from a ``file://`` tree laid out like raw.githubusercontent.com (``--base-url``), each file checked by
``git hash-object``; a file that is not the manifest's blob is refused in one line with nothing left behind; the
pytest helper (tests/large_assets.py) skips an absent asset and fails a stale one."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from large_assets import TOOL, fetch_tool, large_asset

ROOT = Path(__file__).resolve().parents[1]
FILES = {  # path in the repository -> bytes
    "Models/Thing/glTF/Thing.gltf": b'{"asset": {"version": "2.0"}}\n',
    "Models/Thing/glTF/Thing.bin": bytes(range(256)) * 8,
    "Models/Thing/LICENSE.md": b"CC0 1.0 Universal\n",
}

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")


def git(cwd: Path, *args: str, data: bytes | None = None) -> str:
    cmd = ["git", "-c", "user.name=t", "-c", "user.email=t@example.org", "-c", "commit.gpgsign=false", *args]
    return subprocess.run(cmd, cwd=cwd, input=data, capture_output=True, check=True).stdout.decode().strip()


def blob_of(data: bytes, cwd: Path) -> str:
    return git(cwd, "hash-object", "--stdin", data=data)


@pytest.fixture
def repo(tmp_path: Path) -> tuple[Path, str]:
    """A git repository holding FILES in one commit, and that commit."""
    r = tmp_path / "repo"
    for path, data in FILES.items():
        (r / path).parent.mkdir(parents=True, exist_ok=True)
        (r / path).write_bytes(data)
    git(r, "init", "-q")
    git(r, "add", ".")
    git(r, "commit", "-qm", "thing")
    return r, git(r, "rev-parse", "HEAD")


def manifest(tmp_path: Path, commit: str, blobs: dict[str, str]) -> Path:
    files = [{"path": p, "to": Path(p).name, "blob": blobs[p], "bytes": len(d)} for p, d in FILES.items()]
    asset = {"repository": "example/repo", "mirrors": ["example/mirror"], "commit": commit}
    doc = {"assets": {"thing": asset | {"licence": "CC0", "credit": "test", "files": files}}}
    out = tmp_path / "large.json"
    out.write_text(json.dumps(doc))
    return out


def run(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(TOOL), *map(str, args)], capture_output=True, text=True, timeout=60)


def true_blobs(r: Path) -> dict[str, str]:
    return {p: blob_of(d, r) for p, d in FILES.items()}


def test_from_git_fetches_every_file_with_its_blob_id(tmp_path, repo):
    r, commit = repo
    blobs = true_blobs(r)
    m, dest = manifest(tmp_path, commit, blobs), tmp_path / "large"
    done = run("--manifest", m, "--from-git", r, "--dest", dest, "thing")
    assert done.returncode == 0, done.stderr
    for path, data in FILES.items():
        got = dest / "thing" / Path(path).name
        assert got.read_bytes() == data
        assert git(r, "hash-object", str(got)) == blobs[path]
    assert [p.name for p in dest.iterdir()] == ["thing"]  # no temporary folder left
    again = run("--manifest", m, "--from-git", r, "--dest", dest)
    assert again.returncode == 0 and "already in" in again.stdout


def test_a_file_that_is_not_the_manifests_blob_is_refused_and_nothing_is_left(tmp_path, repo):
    r, commit = repo
    blobs = true_blobs(r) | {"Models/Thing/LICENSE.md": blob_of(b"another licence\n", r)}  # the last file read
    m, dest = manifest(tmp_path, commit, blobs), tmp_path / "large"
    refused = run("--manifest", m, "--from-git", r, "--dest", dest)
    assert refused.returncode == 1
    line = refused.stderr.strip()
    assert "\n" not in line and "Models/Thing/LICENSE.md" in line and "nothing written" in line, line
    assert not dest.exists()  # created for the fetch, removed with the partial folder
    dest.mkdir()
    (dest / "other").mkdir()
    assert run("--manifest", m, "--from-git", r, "--dest", dest).returncode == 1
    assert [p.name for p in dest.iterdir()] == ["other"]


def test_download_tries_the_mirror_and_checks_each_blob(tmp_path, repo):
    """The download path over ``file://`` (urllib opens it as it opens https): the repository has no copy, the
    mirror has; then the mirror's last file is corrupted by one byte."""
    r, commit = repo
    m, base = manifest(tmp_path, commit, true_blobs(r)), tmp_path / "raw"
    for path, data in FILES.items():
        (base / "example/mirror" / commit / path).parent.mkdir(parents=True, exist_ok=True)
        (base / "example/mirror" / commit / path).write_bytes(data)
    dest = tmp_path / "large"
    done = run("--manifest", m, "--base-url", base.as_uri(), "--dest", dest)
    assert done.returncode == 0, done.stderr
    assert all((dest / "thing" / Path(p).name).read_bytes() == d for p, d in FILES.items())
    broken = base / "example/mirror" / commit / "Models/Thing/LICENSE.md"
    broken.write_bytes(b"CC0 1.0 Universal\r")
    dest2 = tmp_path / "large2"
    refused = run("--manifest", m, "--base-url", base.as_uri(), "--dest", dest2)
    assert refused.returncode == 1 and "LICENSE.md is blob" in refused.stderr and not dest2.exists()
    missing = run("--manifest", m, "--base-url", (tmp_path / "nowhere").as_uri(), "--dest", dest2)
    assert missing.returncode == 1 and "could not download" in missing.stderr and not dest2.exists()
    assert len(missing.stderr.strip().splitlines()) == 1


def test_a_differing_folder_is_kept_unless_forced(tmp_path, repo):
    r, commit = repo
    m, dest = manifest(tmp_path, commit, true_blobs(r)), tmp_path / "large"
    assert run("--manifest", m, "--from-git", r, "--dest", dest).returncode == 0
    edited = dest / "thing" / "Thing.gltf"
    edited.write_text("{}")
    refused = run("--manifest", m, "--from-git", r, "--dest", dest)
    assert refused.returncode == 1 and "--force" in refused.stderr and edited.read_text() == "{}"
    assert run("--manifest", m, "--from-git", r, "--dest", dest, "--force").returncode == 0
    assert edited.read_bytes() == FILES["Models/Thing/glTF/Thing.gltf"]
    assert [p.name for p in dest.iterdir()] == ["thing"]


def test_from_git_without_the_commit_says_how_to_get_it(tmp_path, repo):
    r, _ = repo
    m = manifest(tmp_path, "0" * 40, true_blobs(r))
    refused = run("--manifest", m, "--from-git", r, "--dest", tmp_path / "large")
    assert refused.returncode == 1 and f"fetch origin {'0' * 40}" in refused.stderr
    assert not (tmp_path / "large").exists()


def test_helper_skips_an_absent_asset_and_fails_a_stale_one(tmp_path, monkeypatch):
    monkeypatch.setenv("MATREMAP_LARGE_ASSETS", str(tmp_path))
    with pytest.raises(pytest.skip.Exception, match="absent; fetch with python tools/fetch_assets.py gltf-SheenCloth"):
        large_asset("gltf-SheenCloth")
    (tmp_path / "gltf-SheenCloth").mkdir()
    (tmp_path / "gltf-SheenCloth" / "SheenCloth.gltf").write_text("{}")
    with pytest.raises(pytest.fail.Exception, match="fetch_assets.py --force gltf-SheenCloth"):
        large_asset("gltf-SheenCloth")


def test_each_manifest_asset_carries_its_licence_and_is_documented():
    readme = (ROOT / "tests" / "data" / "corpus" / "README.md").read_text()
    for name, asset in fetch_tool().load_manifest().items():
        assert "LICENSE.md" in [f.to for f in asset.files], name
        assert asset.licence and asset.credit, name
        assert f"`{name}`" in readme and f"{asset.size / 1e6:.1f} MB" in readme, name
