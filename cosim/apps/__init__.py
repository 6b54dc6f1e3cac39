"""Runnable applications, one module per case kind (``[case] kind``).

Each module has ``prepare(case, case_path)`` (all input checks, no computation) and
``run(case, resolved, case_path, out_dir, resume)``.
"""
