"""Source trees of git revisions for the benchmark comparisons: worktrees, snapshots, their environment.

Used by ``compare.py`` (one tree after the other) and ``paired.py`` (both at once).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_REV = "d737a5f"


# ---------------------------------------------------------------------------------------------- git
def git(*args: str, cwd: Path = ROOT) -> str:
    """Output of one git command in ``cwd`` (stripped); raises with git's message on failure."""
    done = subprocess.run(["git", *args], check=False, cwd=cwd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"git {' '.join(args)} failed: {done.stderr.strip()}")
    return done.stdout.strip()


def resolve(rev: str) -> str:
    """Full commit id of ``rev`` (a clear error for a typo, before any worktree exists)."""
    try:
        return git("rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}")
    except RuntimeError:
        raise RuntimeError(f"{rev!r} is not a commit of {ROOT}") from None


def working_tree_fingerprint(root: Path = ROOT) -> str:
    """A hash of HEAD, the uncommitted diff and the untracked files' names and contents.

    Others may edit the working tree while this runs; comparing the fingerprint before and after says
    whether the timed "new" tree was one state of the code.
    """
    digest = hashlib.sha256(git("rev-parse", "HEAD", cwd=root).encode())
    digest.update(subprocess.run(["git", "diff", "HEAD"], check=False, cwd=root, capture_output=True).stdout)
    for name in git("ls-files", "--others", "--exclude-standard", cwd=root).splitlines():
        path = root / name
        digest.update(name.encode())
        if path.is_file():
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


@dataclass
class Tree:
    """One source tree under test: where it is, what it is, and whether this run created it."""

    label: str  # "old" / "new"
    path: Path
    description: str
    commit: str
    created: bool = False  # a worktree this run added (and must remove)
    dirty: bool = False

    def as_json(self) -> dict:
        return {"path": str(self.path), "description": self.description, "commit": self.commit,
                "dirty": self.dirty}


def add_worktree(label: str, rev: str, trees: list[Tree]) -> Tree:
    """A detached worktree of ``rev`` in a fresh temporary directory, appended to ``trees`` first.

    Appending before ``git worktree add`` means an interrupt at any point still leaves the directory
    in the list that the caller cleans up.
    """
    commit = resolve(rev)
    path = Path(tempfile.mkdtemp(prefix=f"continuum-gym-{label}-{commit[:8]}-"))
    tree = Tree(label, path, f"{rev} ({commit[:8]})", commit, created=True)
    trees.append(tree)
    # git adds into an existing directory only if it is empty; mkdtemp's is.
    git("worktree", "add", "--detach", str(path), commit)
    return tree


def snapshot_working_tree(trees: list[Tree]) -> Tree:
    """The working tree as it is now, frozen: a worktree of HEAD plus the uncommitted edits copied in.

    Timing /work/main in place is at the mercy of whoever edits it meanwhile: numba keys its cache on
    each source file's modification time, so even a save that changes nothing recompiles inside a
    timed run (its seconds and its memory then count as the code's), and a real edit would time other code.
    """
    head = git("rev-parse", "HEAD")
    tree = add_worktree("new", head, trees)
    changed = git("diff", "--name-only", "--no-renames", "HEAD").splitlines()
    untracked = git("ls-files", "--others", "--exclude-standard").splitlines()
    for name in changed + untracked:
        source, target = ROOT / name, tree.path / name
        if source.is_file():
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)
        elif target.exists():  # deleted in the working tree
            target.unlink()
    tree.dirty = bool(changed or untracked)
    tree.description = f"working tree at {head[:8]}" + (
        f" + {len(changed)} changed, {len(untracked)} untracked files (snapshot)" if tree.dirty else " (snapshot)")
    return tree


def remove_worktree(tree: Tree) -> None:
    """Remove a worktree this run added; --force because numba's caches are untracked files."""
    if not tree.created:
        return
    try:
        git("worktree", "remove", "--force", str(tree.path))
    except RuntimeError as error:
        # Also the path of an interrupted or failed ``worktree add``: delete, then let git forget it.
        if (tree.path / ".git").exists():
            print(f"warning: {error}; deleting {tree.path} by hand", file=sys.stderr)
        shutil.rmtree(tree.path, ignore_errors=True)
        subprocess.run(["git", "worktree", "prune"], cwd=ROOT, check=False)
    tree.created = False


# ---------------------------------------------------------------------------------------------- runs
#: Scripts that use public names only, so a tree that predates them runs the newest tree's copy.
PORTABLE_SCRIPTS = ("memory", "batch")


def script_path(tree: Tree, script: str, newest: Tree) -> Path:
    """``<tree>/benchmarks/<script>.py``, or ``newest``'s copy of a portable script ``tree`` lacks."""
    own = tree.path / "benchmarks" / f"{script}.py"
    if own.is_file() or script not in PORTABLE_SCRIPTS:
        return own
    return newest.path / "benchmarks" / f"{script}.py"


def tree_env(tree: Tree) -> dict[str, str]:
    """The environment of a run in ``tree``: its sources first on sys.path, nothing else inherited there."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree.path)
    return env


def check_import(python: str, tree: Tree) -> str:
    """The ``continuum_gym`` package a run in ``tree`` imports; raises unless it is that tree's own."""
    done = subprocess.run([python, "-c", "import continuum_gym; print(continuum_gym.__file__)"],
                          check=False, cwd=tree.path, env=tree_env(tree), capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{tree.label} tree: cannot import continuum_gym:\n{done.stderr[-2000:]}")
    source = Path(done.stdout.strip()).resolve()
    if not source.is_relative_to(tree.path.resolve()):
        raise RuntimeError(f"{tree.label} tree {tree.path} imports continuum_gym from {source}, not its own copy")
    return str(source)
