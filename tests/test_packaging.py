"""Packaging (issue #23): the wheel holds every module and bundled file, and an install of it
works from any folder, with no help from the checkout.

``pyproject.toml`` lists its packages by hand and maps the top-level folders ``flows/``,
``tasks/``, ``storage/`` and ``configs/`` to ``sim2radar.flows`` etc. (README "Package layout").
Two things can go wrong without any other test noticing, since the test suite runs against the
editable install: a new sub-package or data file is left out of the list or the globs (the
wheel silently lacks it), or code finds a file through the checkout's layout rather than through
the package (works in the clone, fails once installed).

Design:

* :func:`test_packages_list_covers_every_package` reads ``pyproject.toml`` with :mod:`tomllib`
  and compares the explicit ``packages`` list with the folders on disk (fast, no build).
* The module fixture ``wheel`` copies the working tree's files (``git ls-files``: tracked and
  untracked-but-not-ignored) into a temporary folder and builds the wheel there with
  ``pip wheel --no-deps --no-build-isolation --no-index``: the ``build/`` and ``*.egg-info``
  leftovers stay in the temporary folder, and edits made to the checkout during the build do
  not race with it.
* :func:`test_wheel_contents` lists the wheel's members: every module of every listed package,
  every bundled config, radar preset, demo-scene file and dashboard page file is in it, and
  nothing is installed outside ``sim2radar/`` (no top-level ``storage`` or ``tasks``).
* :func:`test_wheel_install_runs_from_an_empty_folder` installs the wheel into a fresh venv
  (``--no-deps --no-index``, before the venv can see the project's environment, so pip never
  sees or touches the editable install), then adds a ``.pth`` naming the project venv's
  site-packages so that the dependencies (numpy, torch, prefect, ...) resolve from there. A
  plain path line in a ``.pth`` is added to ``sys.path`` but the ``.pth`` files inside that
  folder are not processed, so the project's editable-install finder stays inactive. From an
  empty working folder holding decoy ``storage/``, ``tasks/``, ``flows/`` and ``configs/``
  packages whose ``__init__.py`` raises, it runs ``sim2radar info``, ``sim2radar presets`` and a
  probe that imports every module of the installed package and loads every bundled config by
  name with its real loader; every module and config file must come from the new venv.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: top-level folders installed under another name (pyproject ``[tool.setuptools.package-dir]``)
MAPPED = {"flows": "sim2radar.flows", "tasks": "sim2radar.tasks",
          "storage": "sim2radar.storage", "configs": "sim2radar.configs"}
#: folders never copied for the build when git cannot list the files
_NOT_SOURCES = (".git", ".venv", "out", "build", "dist", "*.egg-info", "__pycache__", "*.pyc",
                ".pytest_cache", ".ruff_cache", ".prefect")


def _packages(pyproject: Path) -> tuple[list[str], dict[str, str]]:
    setup = tomllib.loads(pyproject.read_text())["tool"]["setuptools"]
    return list(setup["packages"]), dict(setup.get("package-dir", {}))


def _package_folders(root: Path) -> dict[str, Path]:
    """Import name -> folder of every folder holding an ``__init__.py`` under ``sim2radar/`` and
    the mapped top-level folders."""
    found = {}
    for top, name in {"sim2radar": "sim2radar", **MAPPED}.items():
        for init in sorted((root / top).rglob("__init__.py")):
            rel = init.parent.relative_to(root / top)
            if "__pycache__" in rel.parts:
                continue
            found[".".join((name, *rel.parts))] = init.parent
    return found


def test_packages_list_covers_every_package():
    packages, package_dir = _packages(ROOT / "pyproject.toml")
    assert len(packages) == len(set(packages)), "pyproject.toml lists a package twice"
    on_disk = _package_folders(ROOT)
    missing = sorted(set(on_disk) - set(packages))
    assert not missing, f"folders with an __init__.py not in pyproject's packages: {missing}"
    stale = sorted(set(packages) - set(on_disk))
    # the rest are data folders (configs, presets, the demo scene, the dashboard page): listed
    # so setuptools ships them without "Package would be ignored" warnings; each must exist
    # and hold no code
    for name in stale:
        prefix = next((n for n in MAPPED.values() if name.startswith(n + ".")), "sim2radar")
        base = ROOT / {n: f for f, n in MAPPED.items()}.get(prefix, "sim2radar")
        folder = base.joinpath(*name[len(prefix) + 1:].split("."))
        assert folder.is_dir(), f"pyproject lists {name}, but {folder} is not a folder"
        assert not list(folder.glob("*.py")), f"{folder} holds code but no __init__.py"
    assert package_dir == {name: folder for folder, name in MAPPED.items()}
    # a folder of modules without an __init__.py is a namespace package: the explicit list
    # would leave it out of the wheel without a word
    for top in ("sim2radar", *MAPPED):
        for py in (ROOT / top).rglob("*.py"):
            if "__pycache__" not in py.parts:
                assert (py.parent / "__init__.py").is_file(), \
                    f"{py.relative_to(ROOT)}: its folder has no __init__.py (not packaged)"


def _source_files(root: Path) -> list[str] | None:
    """The working tree's files relative to ``root`` (tracked, and untracked but not ignored),
    or None without git."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
            cwd=root, capture_output=True, check=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    return [name for name in out.decode().split("\0") if name]


def _copy_sources(root: Path, dest: Path) -> None:
    names = _source_files(root)
    if names is None:
        shutil.copytree(root, dest, ignore=shutil.ignore_patterns(*_NOT_SOURCES), symlinks=True)
        return
    for name in names:
        src = root / name
        if src.is_file():  # listed by the index but deleted in the working tree: skip
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)


def _clean_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP", "VIRTUAL_ENV")
           and not k.startswith("PIP_")}
    env.update(PIP_DISABLE_PIP_VERSION_CHECK="1", PIP_NO_INPUT="1", PYTHONNOUSERSITE="1")
    env.update(extra)
    return env


def _run(cmd: list[str], *, cwd: Path, env: dict[str, str], timeout: float = 300):
    done = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)
    assert done.returncode == 0, (
        f"{' '.join(map(str, cmd))} exited {done.returncode}\n"
        f"--- stdout\n{done.stdout[-4000:]}\n--- stderr\n{done.stderr[-4000:]}")
    return done


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> tuple[Path, Path]:
    """(the built wheel, the copy of the sources it was built from)."""
    base = tmp_path_factory.mktemp("wheel")
    src, dist = base / "src", base / "dist"
    _copy_sources(ROOT, src)
    _run([sys.executable, "-m", "pip", "wheel", ".", "--no-deps", "--no-build-isolation",
          "--no-index", "-q", "-w", dist], cwd=src, env=_clean_env())
    wheels = sorted(dist.glob("sim2radar-*.whl"))
    assert len(wheels) == 1, f"expected one sim2radar wheel in {dist}, got {wheels}"
    return wheels[0], src


def _expected_members(src: Path) -> set[str]:
    """Wheel paths that must be present, from the copied sources (independent of the globs in
    pyproject: every file of the bundled-data folders, every module of every package)."""
    expected = set()
    for name, folder in _package_folders(src).items():
        for py in folder.glob("*.py"):
            expected.add("/".join((*name.split("."), py.name)))
    for cfg in (src / "configs").rglob("*.yaml"):
        expected.add("sim2radar/configs/" + cfg.relative_to(src / "configs").as_posix())
    for preset in (src / "sim2radar/radar/presets").glob("*.yaml"):
        expected.add(preset.relative_to(src).as_posix())
    expected.add("sim2radar/flows/deployments.yaml")   # `sim2radar deploy` reads it
    # the demo scene and (once it exists) the dashboard's page: every file, any depth
    for folder in ("sim2radar/data", "sim2radar/experiment/page"):
        for path in (src / folder).rglob("*"):
            if path.is_file() and "__pycache__" not in path.parts and path.suffix != ".pyc":
                expected.add(path.relative_to(src).as_posix())
    return expected


def test_wheel_contents(wheel):
    path, src = wheel
    with zipfile.ZipFile(path) as zf:
        members = {name for name in zf.namelist() if not name.endswith("/")}
    expected = _expected_members(src)
    assert any(m.startswith("sim2radar/configs/experiment/") for m in expected)
    assert any(m.startswith("sim2radar/data/demo/") for m in expected)
    missing = sorted(expected - members)
    assert not missing, f"{path.name} lacks {len(missing)} file(s): {missing}"
    outside = sorted(m for m in members
                     if not m.startswith(("sim2radar/", "sim2radar-")))
    assert not outside, f"{path.name} installs files outside sim2radar/: {outside}"
    dist_info = [m for m in members if m.endswith(".dist-info/entry_points.txt")]
    assert dist_info, "no entry_points.txt: the sim2radar command would not be installed"
    with zipfile.ZipFile(path) as zf:
        assert "sim2radar = sim2radar.cli:main" in zf.read(dist_info[0]).decode()


#: run with ``python -c`` in the empty working folder (so that folder is on sys.path, as the
#: decoys need); prints one JSON line
_PROBE = r"""
import importlib, importlib.metadata, json, pkgutil, sys

import sim2radar

failed = {}
def _failed(name):
    failed[name] = repr(sys.exc_info()[1])
for info in pkgutil.walk_packages(sim2radar.__path__, "sim2radar.", onerror=_failed):
    try:
        importlib.import_module(info.name)
    except Exception as exc:
        failed[info.name] = repr(exc)

from sim2radar.configio import CONFIG_KINDS, bundled_configs, config_path
from sim2radar.detect.config import load_config
from sim2radar.experiment.profiles import load_profile
from sim2radar.factory.spec import load_generate_config
from sim2radar.radar.config import PRESET_DIR, load_radar_config, preset_names
from sim2radar.reconstruct.pipeline import ReconstructionConfig
from sim2radar.scenes import demo_scene_paths, load_scene_file
from sim2radar.worlds.config import load_worlds_config
from sim2radar.evaluate.fidelity import heldout_world_seeds

loaders = {"detect": load_config, "experiment": load_profile, "generate": load_generate_config,
           "reconstruct": ReconstructionConfig.from_yaml, "worlds": load_worlds_config,
           "evaluation": heldout_world_seeds}
configs = {}
for kind in CONFIG_KINDS:
    configs[kind] = {}
    for name in bundled_configs(kind):
        loaders[kind](name)  # the real loader, by name
        configs[kind][name] = str(config_path(name, kind))
profile = load_profile("demo")
presets = {name: str(PRESET_DIR / f"{name}.yaml") for name in preset_names()}
for name in presets:
    load_radar_config(name)
scenes = [str(p) for p in demo_scene_paths()]
scene = load_scene_file(scenes[0])
print(json.dumps({
    "failed": failed,
    "modules": {name: getattr(mod, "__file__", None) for name, mod in list(sys.modules.items())},
    "sys_path": sys.path,
    "configs": configs,
    "profile": {"name": profile.name, "detector": str(profile.detector)},
    "presets": presets,
    "scenes": scenes,
    "scene_meshes": len(scene.meshes),
    "dist": str(importlib.metadata.distribution("sim2radar").locate_file("")),
}))
"""


def _under(path: str | Path, folder: Path) -> bool:
    return Path(path).resolve().is_relative_to(folder.resolve())


def _install(wheel_path: Path, tmp_path: Path, *, shadow: bool = False, **extra_env: str
             ) -> tuple[Path, Path, dict[str, str], Path]:
    """The wheel in a fresh venv: (venv folder, its site-packages, its environment, an empty
    working folder holding decoy packages whose ``__init__.py`` raises: ``storage/``,
    ``tasks/``, ``flows/``, ``configs/``, and with ``shadow`` a ``sim2radar/`` too, as a
    checkout used as the working folder would have)."""
    env_dir = tmp_path / "venv"
    # with pip (ensurepip, offline), and without the project's environment at first
    venv.EnvBuilder(with_pip=True, clear=True).create(env_dir)
    python = env_dir / "bin" / "python"
    env = _clean_env(PREFECT_HOME=str(tmp_path / "prefect"), VIRTUAL_ENV=str(env_dir),
                     PATH=f"{env_dir / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
                     **extra_env)
    _run([python, "-m", "pip", "install", "--no-deps", "--no-index", "-q", wheel_path],
         cwd=tmp_path, env=env)
    site = Path(_run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     cwd=tmp_path, env=env).stdout.strip())
    assert _under(site, env_dir)
    # the dependencies, from the project's venv (this interpreter's): path lines only, so the
    # editable install's own .pth (and its finder) in that folder stay unprocessed
    deps = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (site / "_sim2radar_test_deps.pth").write_text("".join(f"{d}\n" for d in sorted(deps)))

    work = tmp_path / "work"
    for decoy in (*MAPPED, *(["sim2radar"] if shadow else [])):
        (work / decoy).mkdir(parents=True)
        (work / decoy / "__init__.py").write_text(
            f"raise RuntimeError('the decoy {decoy}/ in the working folder was imported')\n")
    return env_dir, site, env, work


def test_wheel_install_runs_from_an_empty_folder(wheel, tmp_path):
    path, src = wheel
    env_dir, site, env, work = _install(path, tmp_path)
    python = env_dir / "bin" / "python"

    info = _run([env_dir / "bin" / "sim2radar", "info"], cwd=work, env=env).stdout
    version = tomllib.loads((src / "pyproject.toml").read_text())["project"]["version"]
    assert f"{'sim2radar':10s} {version}" in info.splitlines(), info
    presets_out = _run([env_dir / "bin" / "sim2radar", "presets"], cwd=work, env=env).stdout
    assert "ti-mmwcas" in presets_out

    out = _run([python, "-c", _PROBE], cwd=work, env=env).stdout
    probe = json.loads(out.strip().splitlines()[-1])
    assert not probe["failed"], f"modules that failed to import: {probe['failed']}"

    checkout = ROOT.resolve()
    assert str(checkout) not in probe["sys_path"]
    pkg = site / "sim2radar"
    modules = probe["modules"]
    for name in ("sim2radar", "sim2radar.flows", "sim2radar.tasks", "sim2radar.storage",
                 "sim2radar.configs", "sim2radar.cli", "sim2radar.configio"):
        assert modules.get(name) and _under(modules[name], pkg), f"{name} from {modules.get(name)}"
    ours = {name: f for name, f in modules.items() if name.split(".")[0] == "sim2radar"}
    assert len(ours) > 50
    assert all(f is None or _under(f, pkg) for f in ours.values()), \
        {n: f for n, f in ours.items() if f and not _under(f, pkg)}
    # nothing from the checkout (only the project venv's site-packages, for the dependencies)
    project_env = Path(sys.prefix)
    # (some modules' __file__ is a bare name, e.g. torch.ops: '_ops.py': not a location)
    from_checkout = {n: f for n, f in modules.items() if f and os.path.isabs(f)
                     and _under(f, checkout) and not _under(f, project_env)}
    assert not from_checkout, f"modules imported from the checkout: {from_checkout}"
    decoys = sorted(set(MAPPED) & set(modules))
    assert not decoys, f"the working folder's decoys were imported: {decoys}"
    assert _under(probe["dist"], site), f"sim2radar's metadata from {probe['dist']}"

    # every bundled config by name, from the installed package
    bundled = {kind: sorted(p.stem for p in (src / "configs" / kind).glob("*.yaml"))
               for kind in probe["configs"]}
    assert {kind: sorted(names) for kind, names in probe["configs"].items()} == bundled
    for kind in ("detect", "experiment", "generate", "reconstruct", "worlds"):
        assert probe["configs"].get(kind), f"no bundled {kind} config found by name"
        for name, file in probe["configs"][kind].items():
            assert Path(file) == pkg / "configs" / kind / f"{name}.yaml"
            assert Path(file).is_file()
    assert probe["profile"]["name"] == "demo"
    assert _under(probe["profile"]["detector"], pkg / "configs" / "detect")
    assert probe["presets"] and all(_under(f, pkg / "radar" / "presets")
                                    for f in probe["presets"].values())
    assert probe["scenes"] and all(_under(f, pkg / "data") for f in probe["scenes"])
    assert probe["scene_meshes"] > 0


#: read in the wheel's venv: every deployment's entrypoint, job variables, schedules' activity
_DEPLOYMENTS_PROBE = r"""
import json
from prefect.client.orchestration import get_client
with get_client(sync_client=True) as c:
    out = {}
    for d in c.read_deployments():
        flow = c.read_flow(d.flow_id).name
        out[f"{flow}/{d.name}"] = {"entrypoint": d.entrypoint, "path": d.path,
                                   "job_variables": d.job_variables, "paused": d.paused,
                                   "pull_steps": d.pull_steps,
                                   "active": [s.active for s in d.schedules]}
print(json.dumps(out))
"""


def _stop_group(proc: subprocess.Popen) -> None:
    import signal

    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(timeout=20)
            return
        except subprocess.TimeoutExpired:
            continue


def test_the_installed_wheel_deploys_and_a_worker_runs_a_deployment(wheel, tmp_path):
    """Issue #34: `sim2radar deploy` from a wheel in a fresh venv, no checkout anywhere. The
    deployments reach the managed server with module entrypoints, the working folder given by
    --home and schedules off (a home holding a ``sim2radar/`` package folder, as a checkout
    does, is refused: Prefect would import it instead of the installed package); a process
    worker started in another folder runs radar-on-demand in the home to Completed, and `prefect` finds the managed server through the Prefect profile
    it wrote; --schedule turns a schedule on."""
    from sim2radar.storage import ArtifactStore

    path, _ = wheel
    env_dir, _, env, work = _install(path, tmp_path, shadow=True,
                                     SIM2RADAR_PREFECT_SERVER="managed",
                                     PREFECT_WORKER_QUERY_SECONDS="2",
                                     PREFECT_SERVER_ANALYTICS_ENABLED="false")
    for key in [k for k in env if k.startswith("PREFECT_LOGGING") or k == "PREFECT_API_URL"]:
        del env[key]
    python, cli = env_dir / "bin" / "python", env_dir / "bin" / "sim2radar"
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    home = str(tmp_path / "prefect")
    _run([cli, "server", "start", "--home", home], cwd=elsewhere, env=env, timeout=240)
    worker = None
    try:
        refused = subprocess.run([str(cli), "deploy", "--all", "--home", str(work)],
                                 cwd=elsewhere, env=env, capture_output=True, text=True,
                                 timeout=240)
        assert refused.returncode == 2, refused.stdout + refused.stderr
        assert f"{work.resolve()} holds a sim2radar/ package folder" in refused.stderr
        work = tmp_path / "home"  # harmless decoys (flows/, tasks/ ...), no sim2radar/
        for decoy in MAPPED:
            (work / decoy).mkdir(parents=True)
            (work / decoy / "__init__.py").write_text("raise RuntimeError('decoy imported')\n")
        out = _run([cli, "deploy", "--all", "--home", work], cwd=elsewhere, env=env,
                   timeout=240).stdout
        assert "created the process work pool sim2radar-cpu" in out, out
        assert out.count("deployed ") == 7, out
        # what the server holds (read through the profile the managed server wrote)
        deps = json.loads(_run([python, "-c", _DEPLOYMENTS_PROBE], cwd=elsewhere,
                               env=env).stdout.strip().splitlines()[-1])
        assert len(deps) == 7, sorted(deps)
        for name, dep in deps.items():
            assert dep["entrypoint"].startswith("sim2radar.flows."), (name, dep)
            assert dep["job_variables"]["working_dir"] == str(work.resolve()), (name, dep)
            assert dep["job_variables"]["env"]["SIM2RADAR_HOME"] == str(work.resolve())
            assert not any(dep["active"]), f"{name}: a schedule was registered active"
            assert not dep["paused"]
        assert deps["simulate-dataset/nightly-radar"]["active"] == [False]

        worker = subprocess.Popen(
            [str(python), "-m", "prefect", "worker", "start", "--pool", "sim2radar-cpu"],
            cwd=elsewhere, env=env, stdout=open(tmp_path / "worker.log", "wb"),
            stderr=subprocess.STDOUT, start_new_session=True)
        store = tmp_path / "store"
        try:
            # one `request` parameter: it replaces the deployment's default request whole
            request = {"scenes": ["demo"], "store": str(store), "dataset": "wheel"}
            ran = _run([python, "-m", "prefect", "deployment", "run",
                        "simulate-dataset/radar-on-demand", "-p",
                        f"request={json.dumps(request)}", "--watch", "--watch-interval", "2",
                        "--watch-timeout", "300"], cwd=elsewhere, env=env, timeout=360).stdout
        except AssertionError as exc:
            log = (tmp_path / "worker.log").read_text(errors="replace")[-4000:]
            raise AssertionError(f"{exc}\n--- worker log\n{log}") from None
        assert "Completed" in ran, ran
        (row,) = ArtifactStore(store).manifest("wheel").rows()
        assert (row["scene_id"], row["status"]) == ("demo_corridor", "ok"), row

        again = _run([cli, "deploy", "nightly-radar", "--schedule", "--home", work],
                     cwd=elsewhere, env=env, timeout=240).stdout
        assert "schedules on" in again, again
        deps = json.loads(_run([python, "-c", _DEPLOYMENTS_PROBE], cwd=elsewhere,
                               env=env).stdout.strip().splitlines()[-1])
        assert deps["simulate-dataset/nightly-radar"]["active"] == [True]
        assert deps["generate-dataset/nightly-generate"]["active"] == [False]
    finally:
        if worker is not None:
            _stop_group(worker)
        subprocess.run([str(cli), "server", "stop", "--home", home], cwd=elsewhere, env=env,
                       capture_output=True, timeout=120)
