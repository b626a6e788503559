//! The binary's own commands: check-config, hash-key, openapi.

use std::process::Command;

fn rackd(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rackd")).args(args).output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

#[test]
fn check_config_accepts_the_example_and_names_the_bad_key_and_line() {
    let example = concat!(env!("CARGO_MANIFEST_DIR"), "/config/rackd.example.toml");
    let (ok, out, _) = rackd(&["check-config", example]);
    assert!(ok && out.contains("ok"));

    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[server]\nlisten = \"127.0.0.1:8080\"\n\n[database]\npaht = \"x.db\"\n").unwrap();
    let (ok, _, err) = rackd(&["check-config", bad.to_str().unwrap()]);
    assert!(!ok);
    assert!(err.contains("paht") && err.contains("line 5"), "{err}");

    std::fs::write(&bad, "[server]\nlisten = \"nowhere\"\n").unwrap();
    let (ok, _, err) = rackd(&["check-config", bad.to_str().unwrap()]);
    assert!(!ok && err.contains("listen") && err.contains("line 2"), "{err}");

    std::fs::write(&bad, "[[auth.keys]]\nname = \"x\"\nrole = \"root\"\nhash = \"sha256:00\"\n").unwrap();
    let (ok, _, err) = rackd(&["check-config", bad.to_str().unwrap()]);
    assert!(!ok && err.contains("role"), "{err}");
}

#[test]
fn hash_key_prints_the_configured_form() {
    let (ok, out, _) = rackd(&["hash-key", "secret"]);
    assert!(ok);
    assert_eq!(out.trim(), "sha256:2bb80d537b1da3e38bd30361aa855686bde0eacd7162fef6a25fe97bf527a25b");
    let (ok, out, _) = rackd(&["hash-key", "--generate"]);
    assert!(ok && out.contains("key:  rk_") && out.contains("hash: sha256:"), "{out}");
}

#[test]
fn serve_refuses_a_public_address_without_keys() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("x.db");
    let (ok, _, err) = rackd(&["serve", "--listen", "0.0.0.0:0", "--database", db.to_str().unwrap()]);
    assert!(!ok && err.contains("--insecure"), "{err}");
}
