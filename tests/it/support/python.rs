//! The Python the tests run their Python libraries with (prometheus_client's parsers,
//! standardwebhooks): the virtualenv `cargo xtask test` makes in `.ci/venv` from
//! `.ci/requirements.txt`, unless `RACKD_TEST_PYTHON` names another.

use std::path::PathBuf;

/// A Python that imports `module`: `RACKD_TEST_PYTHON`, else `.ci/venv/bin/python`. When
/// it cannot, the test fails (never skips), saying what `module` is needed `for_what` and
/// how to install it.
pub fn python_with(module: &str, for_what: &str) -> PathBuf {
    let path = std::env::var_os("RACKD_TEST_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(".ci/venv/bin/python"));
    let works = std::process::Command::new(&path)
        .args(["-c", &format!("import {module}")])
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(
        works,
        "{} with {module} is needed {for_what}: run `cargo xtask test` (or `cargo xtask \
         setup`), which makes .ci/venv from .ci/requirements.txt, or point RACKD_TEST_PYTHON \
         at a Python that has it",
        path.display()
    );
    path
}
