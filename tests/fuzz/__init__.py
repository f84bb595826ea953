"""The hostile-input fuzzers (spec/robustness.md): one module per family, each a campaign of its own that the test
suite also drives (a few hundred seeded cases each).

* :mod:`tests.fuzz.readers` — BVH, both exp-map layouts, checkpoints and ONNX files: seeds, mutators, one case
  runner (``tests/test_fuzz_readers.py``, ``tests/test_bvh_strict.py``);
* :mod:`tests.fuzz.math_api` — the math API (``tests/test_fuzz_math.py``);
* :mod:`tests.fuzz.deploy_runtime` — the ONNX runtime wrapper and model-size limits (``tests/test_deploy_fuzz.py``);
* :mod:`tests.fuzz.campaign` — the whole campaign over all families (``tests/test_fuzz_campaign.py``);
* :mod:`tests.fuzz.surfaces` — the surfaces QuaterNet, locomotion and acRNN added: runtime wrappers, per-task
  checkpoint fields, size options, files named on the command line, divergence (issue #28,
  ``tests/test_hostile_surfaces.py``).

Run a campaign from the repository root, e.g. ``python -m tests.fuzz.campaign --scale 1``; each writes its JSON
into ``tests/fuzz/results/``.
"""
