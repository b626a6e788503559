//! `[[webhooks]]` refused at load: every bad entry names its key and line, and no message
//! or `--explain` line carries a secret.

use std::path::Path;

use super::webhooks::{SecretError, WebhookProblem, decode_secret};
use super::*;

const SECRET: &str = "whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw";

/// One good entry, on lines 1 to 5.
fn entry(name: &str) -> String {
    format!(
        "[[webhooks]]\nname = \"{name}\"\nurl = \"https://wms.plant.local/rackd/events\"\n\
         events = [\"job.*\", \"alarm.raised\"]\nsecret = \"{SECRET}\"\n"
    )
}

fn error(text: &str) -> String {
    let err = Config::parse(text, Path::new("x.toml")).unwrap_err().to_string();
    assert!(!err.contains("MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw"), "the secret is never printed: {err}");
    err
}

#[test]
fn a_good_entry_loads_with_its_defaults() {
    let config = Config::parse(&entry("wms"), Path::new("x.toml")).unwrap();
    let w = &config.webhooks[0];
    let written = WebhookConfig { material: None, ..w.clone() };
    assert_eq!(written, WebhookConfig::new("wms", &w.url, &["job.*", "alarm.raised"], SECRET));
    assert_eq!(w.key().unwrap().len(), 24);
    assert_eq!(w.material.as_ref().map(|m| m.key.len()), Some(24), "decoded as it loaded");
    assert_eq!(config.events.webhook_hold_hours, 168);
}

#[test]
fn an_unknown_event_type_is_named_with_the_valid_ones() {
    let err = error(&entry("wms").replace("alarm.raised", "job.created"));
    assert!(err.starts_with("x.toml:4:1: webhooks[0].events: webhooks \"wms\": \"job.created\""), "{err}");
    assert!(err.contains("job.updated, device.updated") && err.contains("job.*, device.*"), "{err}");
    assert!(err.contains("\"*\" for all"), "{err}");
    let err = error(&entry("wms").replace("[\"job.*\", \"alarm.raised\"]", "[]"));
    assert!(err.starts_with("x.toml:4:1: webhooks[0].events: ") && err.contains("empty"), "{err}");
}

#[test]
fn a_url_without_a_host_or_of_another_scheme_is_refused_without_its_password() {
    for url in ["http:///x", "https:", "http:wms/x", "https://", "wms.plant.local/x", "ftp://wms/x"] {
        let err = error(&entry("wms").replace("https://wms.plant.local/rackd/events", url));
        assert!(err.starts_with("x.toml:3:1: webhooks[0].url: "), "{url}: {err}");
    }
    let err = error(&entry("wms").replace("https://wms.plant.local", "ftp://rackd:pw-1234@wms"));
    assert!(err.contains("ftp://rackd:***@wms") && !err.contains("pw-1234"), "{err}");
    let proxy = format!("{}proxy = \"http:///3128\"\n", entry("wms"));
    assert!(error(&proxy).starts_with("x.toml:6:1: webhooks[0].proxy: "), "{}", error(&proxy));
    let ok = format!("{}proxy = \"http://proxy.plant.local:3128\"\n", entry("wms"));
    assert!(Config::parse(&ok, Path::new("x.toml")).is_ok());
}

#[test]
fn a_secret_is_one_of_secret_and_secret_file_and_decodes() {
    let err = error(&entry("wms").replace(SECRET, "whsec_not base64!"));
    assert!(err.starts_with("x.toml:5:1: webhooks[0].secret: ") && err.contains("not base64"), "{err}");
    assert!(!err.contains("not base64!\""), "{err}");
    let err = error(&entry("wms").replace(SECRET, "whsec_c2hvcnQ="));
    assert!(err.starts_with("x.toml:5:1: webhooks[0].secret: ") && err.contains("5 bytes"), "{err}");

    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("wms_secret");
    let from_file =
        entry("wms").replace(&format!("secret = \"{SECRET}\""), &format!("secret_file = {file:?}"));
    let err = error(&from_file);
    assert!(err.starts_with("x.toml:5:1: webhooks[0].secret_file: "), "{err}");
    assert!(err.contains(&format!("{} cannot be read", file.display())), "{err}");
    std::fs::write(&file, format!("{SECRET}\n")).unwrap();
    let config = Config::parse(&from_file, Path::new("x.toml")).unwrap();
    assert_eq!(config.webhooks[0].key().unwrap().len(), 24, "the file's line, trimmed");

    let both = format!("{}secret_file = {file:?}\n", entry("wms"));
    let err = error(&both);
    assert!(err.starts_with("x.toml:6:1: webhooks[0].secret_file: ") && err.contains("not both"), "{err}");
    let neither = entry("wms").replace(&format!("secret = \"{SECRET}\"\n"), "");
    let err = error(&neither);
    assert!(err.starts_with("x.toml:1:1: webhooks[0].secret: "), "the entry's line: {err}");
}

#[test]
fn names_are_short_plain_and_unique() {
    let err = error(&format!("{}\n{}", entry("wms"), entry("wms")));
    assert!(err.starts_with("x.toml:8:1: webhooks[1].name: webhooks: name \"wms\" is used twice"), "{err}");
    for name in ["", "w m s", "wms/1", &"w".repeat(65)] {
        let err = error(&entry(name));
        assert!(err.starts_with("x.toml:2:1: webhooks[0].name: "), "{name:?}: {err}");
    }
    assert!(Config::parse(&entry(&format!("Wms_2-{}", "w".repeat(58))), Path::new("x.toml")).is_ok());
}

#[test]
fn times_are_at_least_1_and_the_ca_file_is_read() {
    for key in ["timeout_ms", "backoff_ms", "max_backoff_ms", "alarm_after_secs"] {
        let err = error(&format!("{}{key} = 0\n", entry("wms")));
        assert!(err.starts_with(&format!("x.toml:6:1: webhooks[0].{key}: ")), "{err}");
        assert!(err.ends_with(&format!("{key} must be at least 1")), "{err}");
    }
    let err = error(&format!("{}backoff_ms = 2000\nmax_backoff_ms = 1000\n", entry("wms")));
    assert!(err.starts_with("x.toml:7:1: webhooks[0].max_backoff_ms: "), "{err}");
    let err = error(&format!("{}ca_file = \"/nonexistent/ca.pem\"\n", entry("wms")));
    assert!(
        err.starts_with("x.toml:6:1: webhooks[0].ca_file: ") && err.contains("/nonexistent/ca.pem"),
        "{err}"
    );
    let err = error("[events]\nwebhook_hold_hours = 0\n");
    assert!(err.starts_with("x.toml:2:1: events.webhook_hold_hours: "), "{err}");
}

#[test]
fn explain_shows_the_secret_and_a_url_password_as_stars() {
    let text = format!("{}proxy = \"http://rackd:proxy-pw@proxy:3128\"\n", entry("wms"))
        .replace("https://wms.plant.local", "https://rackd:url-pw@wms.plant.local");
    let loaded = Sources::file(Path::new("x.toml")).load_text(Some(text)).unwrap();
    let out = loaded.explain();
    let line = |start: &str| out.lines().find(|l| l.starts_with(start)).unwrap_or_else(|| panic!("{out}"));
    assert!(line("secret = ").starts_with("secret = \"***\"") && line("secret = ").ends_with("# x.toml:5:1"));
    assert!(line("url = ").contains("https://rackd:***@wms.plant.local/rackd/events"), "{out}");
    assert!(line("proxy = ").contains("http://rackd:***@proxy:3128"), "{out}");
    assert!(line("timeout_ms = 5000").ends_with("# default"), "{out}");
    assert!(!out.contains("MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw") && !out.contains("-pw@"), "{out}");
}

#[test]
fn the_secret_file_and_the_ca_file_are_read_once_as_the_configuration_loads() {
    let dir = tempfile::tempdir().unwrap();
    let (secret, ca) = (dir.path().join("wms_secret"), dir.path().join("wms-ca.pem"));
    std::fs::write(&secret, format!("{SECRET}\n")).unwrap();
    let authority = rcgen::generate_simple_self_signed(vec!["wms-ca".into()]).unwrap();
    std::fs::write(&ca, authority.cert.pem()).unwrap();
    let text = entry("wms").replace(&format!("secret = \"{SECRET}\""), &format!("secret_file = {secret:?}"));
    let config = Config::parse(&format!("{text}ca_file = {ca:?}\n"), Path::new("x.toml")).unwrap();
    // The site's tooling rotates them away; what was loaded stays what the subscription uses.
    std::fs::remove_file(&secret).unwrap();
    std::fs::remove_file(&ca).unwrap();
    let w = &config.webhooks[0];
    assert_eq!(w.key().unwrap(), decode_secret(SECRET).unwrap());
    let roots = w.roots().unwrap().expect("the CA file's certificate");
    assert_eq!(roots, vec![authority.cert.der().clone()]);
    assert!(w.check().is_ok(), "checked against what was loaded");
    assert!(!format!("{w:?}").contains("MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw"));
    // Built in code, with nothing loaded: read when asked, and so missed.
    let bare = WebhookConfig { material: None, ..w.clone() };
    assert!(matches!(bare.material(), Err(WebhookProblem::Secret(SecretError::Read { .. }))));
}
