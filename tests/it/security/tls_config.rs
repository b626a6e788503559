//! `check-config` refuses a TLS setting the build cannot honour (finding: a `sslmode` the
//! driver does not implement, a CA file that is missing or not a certificate, or
//! `verify-full` without a CA, were only found at connection time, if at all).

use std::path::Path;
use std::process::Command;

fn check(file: &Path, text: &str) -> Result<(), String> {
    std::fs::write(file, text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(["check-config", file.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    if out.status.success() { Ok(()) } else { Err(err) }
}

fn quoted(path: &Path) -> String {
    toml::Value::String(path.display().to_string()).to_string()
}

#[test]
fn database_tls_settings_are_checked_before_anything_connects() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.toml");
    let ca = crate::support::tls::Ca::new("site CA").write(dir.path(), "ca.pem");
    let not_pem = dir.path().join("not.pem");
    std::fs::write(&not_pem, "hello\n").unwrap();
    let garbled = dir.path().join("garbled.pem");
    std::fs::write(&garbled, "-----BEGIN CERTIFICATE-----\nAAAA\n-----END CERTIFICATE-----\n").unwrap();
    let url = "postgres://rackd@db.plant/rackd";

    check(&file, &format!("[database]\nurl = \"{url}?sslmode=verify-full\"\nca_file = {}\n", quoted(&ca)))
        .unwrap();
    check(&file, &format!("[database]\nurl = \"{url}?sslmode=require\"\n")).unwrap();

    // sslmode=allow: the driver never tries TLS with it, whatever libpq would do.
    let err = check(&file, &format!("[database]\nurl = \"{url}?sslmode=allow\"\n")).unwrap_err();
    assert!(err.contains("site.toml:2:1: database.url: ") && err.contains("allow"), "{err}");
    let err = check(&file, &format!("[database]\nurl = \"{url}?sslmode=sometimes\"\n")).unwrap_err();
    assert!(err.contains("database.url: ") && err.contains("sometimes"), "{err}");

    // verify-full needs a CA to verify with.
    let err = check(&file, &format!("[database]\nurl = \"{url}?sslmode=verify-full\"\n")).unwrap_err();
    assert!(err.contains("database.url: ") && err.contains("database.ca_file"), "{err}");

    // The CA file exists and holds certificates.
    let missing = dir.path().join("missing.pem");
    for bad in [&missing, &not_pem, &garbled] {
        let text = format!("[database]\nurl = \"{url}?sslmode=verify-full\"\nca_file = {}\n", quoted(bad));
        let err = check(&file, &text).unwrap_err();
        assert!(err.contains("site.toml:3:1: database.ca_file: "), "{}: {err}", bad.display());
        assert!(err.contains(&bad.display().to_string()), "{err}");
    }
    // A CA in the URL is checked the same way.
    let text = format!("[database]\nurl = \"{url}?sslmode=verify-ca&sslrootcert={}\"\n", not_pem.display());
    let err = check(&file, &text).unwrap_err();
    assert!(err.contains("database.url: ") && err.contains(&not_pem.display().to_string()), "{err}");
}

#[test]
fn the_clusters_ca_file_is_checked_too() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("node.toml");
    let ca = crate::support::tls::Ca::new("site CA").write(dir.path(), "ca.pem");
    let head =
        "[database]\nurl = \"postgres://rackd@db.plant/rackd?sslmode=require\"\n[cluster]\nnode = \"a\"\n";
    check(&file, &format!("{head}ca_file = {}\n", quoted(&ca))).unwrap();
    let missing = dir.path().join("missing.pem");
    let err = check(&file, &format!("{head}ca_file = {}\n", quoted(&missing))).unwrap_err();
    assert!(err.contains("node.toml:5:1: cluster.ca_file: ") && err.contains("missing.pem"), "{err}");
    let err = check(&file, &format!("{head}url = \"ftp://10.0.0.1:8080\"\n")).unwrap_err();
    assert!(err.contains("cluster.url: ") && err.contains("https"), "{err}");
}
