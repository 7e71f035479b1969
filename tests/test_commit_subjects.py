"""``.ci/check_commit_subjects`` on small repositories made here, with subjects of known
lengths: it lists exactly the subjects over 72 characters after the base commit."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / ".ci" / "check_commit_subjects"
ENV = {
    **os.environ,
    "GIT_AUTHOR_NAME": "t",
    "GIT_AUTHOR_EMAIL": "t@example.org",
    "GIT_COMMITTER_NAME": "t",
    "GIT_COMMITTER_EMAIL": "t@example.org",
    "GIT_CONFIG_GLOBAL": os.devnull,
    "GIT_CONFIG_NOSYSTEM": "1",
}

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="needs git")


def git(repo: Path, *args: str) -> str:
    return subprocess.run(
        ["git", "-C", str(repo), *args], env=ENV, check=True, capture_output=True, text=True
    ).stdout.strip()


def commit(repo: Path, message: str) -> str:
    git(repo, "commit", "-q", "--allow-empty", "-m", message)
    return git(repo, "rev-parse", "--short", "HEAD")


def check(repo: Path, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """The script as the repository's own ``.ci/check_commit_subjects``, run from ``cwd``."""
    return subprocess.run(
        [sys.executable, str(repo / ".ci" / "check_commit_subjects"), *args],
        cwd=cwd,
        env=ENV,
        capture_output=True,
        text=True,
    )


@pytest.fixture
def repo(tmp_path: Path) -> tuple[Path, str, dict[str, str]]:
    """A repository whose base commit's subject is too long (it predates the rule), and
    after it: subjects of 72 and 73 characters, 72 characters of which two take two bytes,
    a default merge subject of 80 characters and a merge subject of 73 written by hand."""
    r = tmp_path / "repo"
    r.mkdir()
    git(r, "init", "-q", "-b", "main")
    (r / ".ci").mkdir()
    shutil.copy(SCRIPT, r / ".ci" / "check_commit_subjects")
    git(r, "add", ".ci")
    base = commit(r, "b" * 90)
    ids = {"72": commit(r, "x" * 72), "73": commit(r, "y" * 73 + "\n\nbody " + "z" * 100)}
    ids["utf8"] = commit(r, "χ²" + "u" * 70)
    branch = "a-branch-name-long-enough-for-git-s-default-merge-subject-to-pass"
    git(r, "checkout", "-q", "-b", branch)
    commit(r, "side")
    git(r, "checkout", "-q", "main")
    commit(r, "main moves on")
    git(r, "merge", "-q", "--no-ff", "--no-edit", branch)
    default = git(r, "log", "-1", "--format=%s")
    assert default == f"Merge branch '{branch}'" and len(default) == 80
    ids["merge"] = git(r, "rev-parse", "--short", "HEAD")
    git(r, "checkout", "-q", "-b", "other", "HEAD~1")
    commit(r, "other side")
    git(r, "checkout", "-q", "main")
    git(r, "merge", "-q", "--no-ff", "-m", "m" * 73, "other")
    ids["merge73"] = git(r, "rev-parse", "--short", "HEAD")
    return r, base, ids


def test_lists_each_subject_over_72_characters_after_the_base(repo, tmp_path):
    r, base, ids = repo
    done = check(r, base, cwd=tmp_path)  # from outside the repository
    assert done.returncode == 1, done.stderr
    assert sorted(done.stdout.splitlines()) == sorted(
        [f"{ids['merge73']} 73 characters: {'m' * 73}", f"{ids['73']} 73 characters: {'y' * 73}"]
    )
    assert f"2 of 8 commit subjects after {base} are longer than 72" in done.stderr


def test_passes_when_every_subject_fits(repo):
    """After the 73: the subject of 72 characters in 74 bytes, two short ones and git's
    default merge subject of 80 characters, which is not checked."""
    r, _, ids = repo
    git(r, "checkout", "-q", ids["merge"])
    done = check(r, ids["73"], cwd=r / ".ci")
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout == f"4 commit subjects after {ids['73']}: all at most 72 characters\n"


def test_shallow_clone_without_the_base_checks_what_it_holds(repo, tmp_path):
    r, base, ids = repo
    clone = tmp_path / "clone"
    git(tmp_path, "clone", "-q", "--depth", "1", f"file://{r}", str(clone))
    done = check(clone, base)
    assert "is not in this shallow clone" in done.stderr
    assert done.returncode == 1 and done.stdout.split()[0] == ids["merge73"]
    assert "1 of 1 commit subjects in this shallow clone" in done.stderr


def test_a_base_missing_from_a_full_clone_is_an_error(repo):
    r, _, _ = repo
    done = check(r, "0" * 40)
    assert done.returncode == 2 and "is not a commit of" in done.stderr
