"""Cache keys: the code that computes a cached result is one of its inputs."""

from pathlib import Path

from hamsa import shapes
from hamsa.cache import code_fingerprint


def _package(root, files):
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


def test_the_fingerprint_follows_every_source_file_and_nothing_else(tmp_path):
    files = {"__init__.py": "x = 1\n", "sub/module.py": "def f():\n    return 2\n", "notes.txt": "a"}
    base = code_fingerprint(_package(tmp_path / "a", files))
    assert code_fingerprint(_package(tmp_path / "b", files)) == base  # the folder's own name does not count
    assert code_fingerprint(_package(tmp_path / "c", {**files, "notes.txt": "b"})) == base  # not Python source
    assert code_fingerprint(_package(tmp_path / "d", {**files, "sub/module.py": "def f():\n    return 3\n"})) != base
    renamed = {"__init__.py": "x = 1\n", "sub/other.py": files["sub/module.py"], "notes.txt": "a"}
    assert code_fingerprint(_package(tmp_path / "e", renamed)) != base
    assert code_fingerprint(_package(tmp_path / "f", {**files, "extra.py": ""})) != base


def test_the_installed_package_has_one_fingerprint():
    import hamsa

    first = code_fingerprint()
    assert len(first) == 64 and first == code_fingerprint()
    assert first == code_fingerprint(Path(hamsa.__file__).parent)


def _edited_code(monkeypatch, module):
    """Pretend hamsa's source changed, as seen by ``module``'s cache keys."""
    monkeypatch.setattr(module, "code_fingerprint", lambda: "0" * 64)


def test_an_eigenbasis_cached_by_other_code_is_recomputed(tmp_path, monkeypatch):
    import hamsa.datasets as datasets

    mesh = shapes.icosphere(2)
    before = datasets.basis_key(mesh, 6)
    datasets.cached_eigenbasis(mesh, 6, tmp_path)
    _edited_code(monkeypatch, datasets)
    assert datasets.basis_key(mesh, 6) != before
    datasets.cached_eigenbasis(mesh, 6, tmp_path)
    assert len(list(tmp_path.glob("*.npz"))) == 2  # a second entry: the first was not reused


def test_benchmark_pairs_and_experiments_are_keyed_by_the_code(monkeypatch):
    import hamsa.paper.benchmark as benchmark
    import hamsa.paper.reproduce as reproduce
    from hamsa.paper.experiments import EXPERIMENTS

    settings = {"k": 30, "methods": ["hks"], "points": 100, "cache": "bases"}
    experiment = EXPERIMENTS[0]
    keys = benchmark._settings_key(settings), reproduce.input_key(experiment, None, True)
    assert reproduce.input_key(EXPERIMENTS[1], None, True) != keys[1]
    _edited_code(monkeypatch, benchmark)
    _edited_code(monkeypatch, reproduce)
    assert benchmark._settings_key(settings) != keys[0]
    assert reproduce.input_key(experiment, None, True) != keys[1]


def test_the_fingerprint_is_read_once(tmp_path, monkeypatch):
    """Keys are computed per pair and per experiment: the package's files are not reread each time."""
    root = _package(tmp_path, {"__init__.py": "x = 1\n"})
    reads = []
    original = Path.read_bytes
    monkeypatch.setattr(Path, "read_bytes", lambda self: reads.append(self) or original(self))
    values = {code_fingerprint(root) for _ in range(3)}
    assert len(values) == 1 and len(reads) == 1
