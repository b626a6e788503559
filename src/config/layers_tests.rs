//! Layering order, where values came from, and every check naming its key and line.

use std::path::Path;

use super::*;

fn vars(list: &[(&str, &str)]) -> Vec<(String, String)> {
    list.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect()
}

fn load(text: &str, env: &[(&str, &str)]) -> Result<Loaded, ConfigError> {
    let sources = Sources { env: vars(env), ..Sources::file(Path::new("x.toml")) };
    sources.load_text(Some(text.to_owned()))
}

fn error(text: &str) -> String {
    load(text, &[]).unwrap_err().to_string()
}

const FILE: &str = "[server]\nlisten = \"127.0.0.1:1\"\n[database]\npath = \"file.db\"\n";

#[test]
fn defaults_then_file_then_environment_then_command_line() {
    let listen = |l: &Loaded| (l.config.server.listen.to_string(), l.origin("server.listen").to_string());
    let file = load(FILE, &[]).unwrap();
    assert_eq!(listen(&file), ("127.0.0.1:1".into(), "x.toml:2:1".into()));
    assert_eq!(file.origin("server.request_timeout_secs"), Origin::Default);
    assert_eq!(file.config.server.request_timeout_secs, 30);

    let env = [("RACKD_SERVER__LISTEN", "127.0.0.1:2"), ("RACKD_INTAKE__QUEUE", "7")];
    let over = load(FILE, &env).unwrap();
    assert_eq!(listen(&over), ("127.0.0.1:2".into(), "env RACKD_SERVER__LISTEN".into()));
    assert_eq!((over.config.intake.queue, over.config.database.path.to_str()), (7, Some("file.db")));

    let cli = Sources {
        env: vars(&env),
        listen: Some("127.0.0.1:3".parse().unwrap()),
        database: Some("cli.db".into()),
        ..Sources::file(Path::new("x.toml"))
    };
    let top = cli.load_text(Some(FILE.into())).unwrap();
    assert_eq!(listen(&top), ("127.0.0.1:3".into(), "command line".into()));
    assert_eq!(top.config.database.path, Path::new("cli.db"));
    assert_eq!(top.origin("intake.queue").to_string(), "env RACKD_INTAKE__QUEUE");
}

#[test]
fn without_a_file_the_demo_site_with_the_environment() {
    let sources = Sources { env: vars(&[("RACKD_EVENTS__BUFFER", "9")]), ..Sources::default() };
    let demo = sources.load().unwrap();
    assert_eq!(demo.config.site, Config::demo().site);
    assert_eq!(demo.config.events.buffer, 9);
    assert_eq!(demo.origin("site.aisles[1].bays"), Origin::Default);
}

#[test]
fn the_environment_is_checked_like_the_file_and_named() {
    let err = load(FILE, &[("RACKD_SERVER__LISSEN", "x")]).unwrap_err().to_string();
    assert!(err.starts_with("env RACKD_SERVER__LISSEN: server.lissen: unknown field"), "{err}");
    let err = load(FILE, &[("RACKD_INTAKE__QUEUE", "lots")]).unwrap_err().to_string();
    assert!(err.starts_with("env RACKD_INTAKE__QUEUE: intake.queue: "), "{err}");
    let err = load(FILE, &[("RACKD_INTAKE__QUEUE", "0")]).unwrap_err().to_string();
    assert!(err.starts_with("env RACKD_INTAKE__QUEUE: intake.queue: "), "{err}");
    let err = load(FILE, &[("RACKD_SERVR__LISTEN", "x")]).unwrap_err().to_string();
    assert!(err.starts_with("env RACKD_SERVR__LISTEN: servr: unknown field"), "{err}");
    let err = load(FILE, &[("RACKD_LISTEN", "0.0.0.0:8080")]).unwrap_err();
    assert!(matches!(err, ConfigError::Env(EnvError::Retired { .. })), "{err}");
}

fn device(protocol: &str, address: &str, extra: &str) -> String {
    format!(
        "[[devices]]\nid = \"d\"\nkind = \"tags\"\nprotocol = \"{protocol}\"\naddress = \"{address}\"\n{extra}[devices.tags]\nx = \"4x1\"\n"
    )
}

#[test]
fn addresses_are_checked_with_their_line() {
    let err = error(&device("modbus-tcp", "192.168.1.300:502", ""));
    assert!(err.starts_with("x.toml:5:1: devices[0].address: ") && err.contains("IPv4"), "{err}");
    let err = error(&device("modbus-tcp", "192.168.1.10", ""));
    assert!(err.starts_with("x.toml:5:1: devices[0].address: ") && err.contains("no port"), "{err}");
    let err = error(&device("modbus-rtu", "10.0.0.1:502", ""));
    assert!(err.starts_with("x.toml:5:1: devices[0].address: ") && err.contains("modbus-rtu-tcp"), "{err}");
    assert!(load(&device("modbus-rtu", "/dev/ttyUSB0", "serial = \"19200,8E1\"\n"), &[]).is_ok());
}

#[test]
fn serial_settings_only_on_serial_protocols() {
    let err = error(&device("modbus-udp", "10.0.0.1:502", "serial = \"9600,8E1\"\n"));
    assert!(
        err.starts_with("x.toml:6:1: devices[0].serial: ") && err.contains("serial settings apply to"),
        "{err}"
    );
    assert!(load(&device("modbus-rtu-tcp", "10.0.0.1:4001", "serial = \"9600,8E1\"\n"), &[]).is_ok());
}

#[test]
fn units_are_checked_per_protocol_with_their_line() {
    let cases = [
        ("modbus-udp", "10.0.0.1:502", 300, "0..=255"),
        ("modbus-rtu-tcp", "10.0.0.1:4001", 248, "1..=247"),
        ("modbus-rtu", "/dev/ttyS0", 0, "broadcast"),
        ("mewtocol", "/dev/ttyS0", 100, "1..=99"),
        ("ppi", "/dev/ttyS0", 127, "1..=126"),
    ];
    for (protocol, address, unit, range) in cases {
        let err = error(&device(protocol, address, &format!("unit = {unit}\n")));
        assert!(err.starts_with("x.toml:6:1: devices[0].unit: "), "{protocol}: {err}");
        assert!(err.contains(range) && !err.contains("u8"), "{protocol}: {err}");
    }
    let crane = "[[devices]]\nid = \"c\"\nkind = \"crane\"\naddress = \"10.0.0.1:8000\"\nunit = 5\n";
    let err = error(crane);
    assert!(err.starts_with("x.toml:5:1: devices[0].unit: ") && err.contains("no unit"), "{err}");
}

#[test]
fn mewtocols_global_station_is_written_ee() {
    let mewtocol = |protocol: &str, address: &str, unit: &str| {
        format!(
            "[[devices]]\nid = \"d\"\nkind = \"tags\"\nprotocol = \"{protocol}\"\naddress = \"{address}\"\n\
             unit = {unit}\n[devices.tags]\nx = \"DT1\"\n"
        )
    };
    let loaded = load(&mewtocol("mewtocol-tcp", "10.0.0.1:4001", "\"EE\""), &[]).unwrap();
    assert_eq!(loaded.config.devices[0].link().unit, 238);
    let shown = toml::to_string(&loaded.config).unwrap();
    assert!(shown.contains("unit = \"EE\""), "written back as EE: {shown}");
    let lower = load(&mewtocol("mewtocol", "/dev/ttyS0", "\"ee\""), &[]).unwrap();
    assert_eq!(lower.config.devices[0].link().unit, 238);
    let err = error(&device("modbus-tcp", "10.0.0.1:502", "unit = \"EE\"\n"));
    assert!(err.contains("devices[0].unit") && err.contains("global station"), "{err}");
    let err = error(&mewtocol("mewtocol", "/dev/ttyS0", "\"FF\""));
    assert!(err.contains("a station number, or \"EE\""), "{err}");
}

#[test]
fn a_key_of_another_kind_is_named_at_its_line() {
    let crane = "[[devices]]\nid = \"c\"\nkind = \"crane\"\naddress = \"10.0.0.1:8000\"\n\nstride = 1\n";
    let err = error(crane);
    assert!(err.starts_with("x.toml:6:1: devices[0].stride: ") && err.contains("shelf devices"), "{err}");
}

const KEY: &str = "sha256:2bb80d537b1da3e38bd30361aa855686bde0eacd7162fef6a25fe97bf527a25b";

#[test]
fn keys_file_keys_join_the_inline_ones_and_repeats_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let keys = dir.path().join("keys.toml");
    let entry = |name: &str, hash: &str| {
        format!("[[keys]]\nname = \"{name}\"\nrole = \"admin\"\nhash = \"{hash}\"\n")
    };
    std::fs::write(&keys, entry("ops", KEY)).unwrap();
    let inline = format!(
        "[auth]\nkeys_file = {:?}\n[[auth.keys]]\nname = \"wms\"\nrole = \"operator\"\nhash = \"sha256:{}\"\n",
        keys.display(),
        "1".repeat(64)
    );
    let loaded = load(&inline, &[]).unwrap();
    let names: Vec<_> = loaded.config.auth.keys.iter().map(|k| k.name.as_str()).collect();
    assert_eq!(names, ["wms", "ops"]);
    assert_eq!(loaded.origin("auth.keys[1].name").to_string(), format!("{}:2:1", keys.display()));

    std::fs::write(&keys, entry("wms", KEY)).unwrap();
    let err = error(&inline);
    assert_eq!(
        err,
        format!(
            "{}:2:1: auth.keys[1].name: this key's name is also the name of the key at x.toml:4:1",
            keys.display()
        )
    );

    std::fs::write(&keys, entry("ops", KEY).replace("admin", "root")).unwrap();
    let err = error(&inline);
    assert!(
        err.starts_with(&format!("{}:3:8: keys[0].role: ", keys.display())) && err.contains("root"),
        "{err}"
    );

    std::fs::write(&keys, "").unwrap();
    let err = error(&inline);
    assert!(err.starts_with("x.toml:2:1: auth.keys_file: ") && err.contains("names no key"), "{err}");
    let from_env = load(FILE, &[("RACKD_AUTH__KEYS_FILE", "/nonexistent/keys")]).unwrap_err().to_string();
    assert!(from_env.starts_with("cannot read /nonexistent/keys"), "{from_env}");
}

#[test]
fn explain_names_every_origin_and_reads_back_as_the_same_configuration() {
    let example =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/config/rackd.example.toml")).unwrap();
    let loaded = load(&example, &[("RACKD_INTAKE__QUEUE", "99")]).unwrap();
    let text = loaded.explain();
    let line = |start: &str| {
        text.lines().find(|l| l.starts_with(start)).unwrap_or_else(|| panic!("{start}: {text}"))
    };
    assert!(line("queue = 99").ends_with("# env RACKD_INTAKE__QUEUE"), "{text}");
    let listen_line = example.lines().position(|l| l.starts_with("listen =")).unwrap() + 1;
    assert!(line("listen = \"127.0.0.1:8080\"").ends_with(&format!("# x.toml:{listen_line}:1")), "{text}");
    assert!(line("\"beacon.red\" = { address = \"Q0.1\" }").contains("# x.toml:"), "{text}");
    let again = Config::parse(&text, Path::new("explained")).unwrap();
    assert_eq!(again, loaded.config);

    let bare = load("[[devices]]\nid = \"s\"\nkind = \"shelf\"\naddress = \"10.0.0.1:502\"\n", &[]).unwrap();
    let text = bare.explain();
    assert!(text.contains("slots = 60") && text.contains("# default"), "{text}");
    assert!(text.lines().any(|l| l.starts_with("id = \"s\"") && l.ends_with("# x.toml:2:1")), "{text}");
}

#[test]
fn a_database_url_must_be_postgres_and_may_come_from_the_environment() {
    let url = "postgres://rackd:pw@db.plant/rackd";
    let env = load(FILE, &[("RACKD_DATABASE__URL", url)]).unwrap();
    assert_eq!(env.config.database.url.as_deref(), Some(url));
    let err = error("[database]\nurl = \"sqlite:x.db\"\n");
    assert!(err.contains("x.toml:2:1: database.url: database.url is for PostgreSQL"), "{err}");
    let err = error("[database]\nurl = \"mysql://h/db\"\n");
    assert!(err.contains("database.url") && err.contains("is not a postgres:// URL"), "{err}");
}

#[test]
fn a_sqlite_vfs_is_for_the_sqlite_file_only() {
    let env = load(FILE, &[("RACKD_DATABASE__SQLITE_VFS", "unix-excl")]).unwrap();
    assert_eq!(env.config.database.sqlite_vfs.as_deref(), Some("unix-excl"));
    let err = error("[database]\nurl = \"postgres://h/db\"\nsqlite_vfs = \"unix\"\n");
    assert!(err.contains("x.toml:3:1: database.sqlite_vfs: is for the SQLite file"), "{err}");
    let err = error("[database]\nsqlite_vfs = \"\"\n");
    assert!(err.contains("database.sqlite_vfs: names no VFS"), "{err}");
}

#[test]
fn allowed_hosts_from_the_file_or_the_environment_and_the_failure_limit_are_checked() {
    let hosts = |l: &Loaded| l.config.server.allowed_hosts.iter().map(|h| h.to_string()).collect::<Vec<_>>();
    let file = load("[server]\nallowed_hosts = [\"WCS.plant.local\", \"10.1.2.3:8080\"]\n", &[]).unwrap();
    assert_eq!(hosts(&file), ["wcs.plant.local", "10.1.2.3:8080"]);
    let env = load(FILE, &[("RACKD_SERVER__ALLOWED_HOSTS", "wcs, [::1]:9000")]).unwrap();
    assert_eq!(hosts(&env), ["wcs", "[::1]:9000"]);
    let again = Config::parse(&env.explain(), Path::new("explained")).unwrap();
    assert_eq!(again.server.allowed_hosts, env.config.server.allowed_hosts, "--explain reads back");
    let err = error("[server]\nallowed_hosts = [\"http://wcs\"]\n");
    assert!(err.contains("server.allowed_hosts") && err.contains("http://wcs"), "{err}");

    assert_eq!(load(FILE, &[]).unwrap().config.auth.max_failures, 10);
    let err = error("[auth]\nmax_failures = 101\n");
    assert!(err.contains("auth.max_failures") && err.contains("100"), "{err}");
    let err = error("[auth]\nfailure_window_secs = 0\n");
    assert!(err.contains("auth.failure_window_secs"), "{err}");
    assert!(load("[auth]\nmax_failures = 0\nfailure_window_secs = 0\n", &[]).is_ok(), "no limit, no window");
}

#[test]
fn capture_bounds_are_checked() {
    let err = error("[server]\ncapture_downloads = 0\n");
    assert!(err.starts_with("x.toml:2:1: server.capture_downloads: "), "{err}");
    let err = error("[retention]\ncaptures_max_bytes = 1048575\n");
    assert!(err.starts_with("x.toml:2:1: retention.captures_max_bytes: ") && err.contains("1 MiB"), "{err}");
    let err = error("[retention]\nalarm_capture_interval_secs = 604801\n");
    assert!(err.starts_with("x.toml:2:1: retention.alarm_capture_interval_secs: "), "{err}");
    let text = "[server]\ncapture_downloads = 8\n[retention]\ncaptures_max_bytes = 1048576\nalarm_capture_interval_secs = 0\n";
    let config = load(text, &[]).unwrap().config;
    assert_eq!(config.server.capture_downloads, 8);
    assert_eq!(
        (config.retention.captures_max_bytes, config.retention.alarm_capture_interval_secs),
        (1 << 20, 0)
    );
}

#[test]
fn server_timers_cap_and_tls_files_come_from_the_environment_and_are_checked() {
    let err = load(FILE, &[("RACKD_SERVER__HEADER_TIMEOUT_MS", "0")]).unwrap_err().to_string();
    assert!(err.starts_with("env RACKD_SERVER__HEADER_TIMEOUT_MS: server.header_timeout_ms: "), "{err}");
    let err = error("[server]\nmax_connections = 0\n");
    assert!(err.starts_with("x.toml:2:1: server.max_connections: "), "{err}");

    let dir = tempfile::tempdir().unwrap();
    let made = rcgen::generate_simple_self_signed(vec!["localhost".into()]).unwrap();
    let (cert, key) = (dir.path().join("c.pem"), dir.path().join("k.pem"));
    std::fs::write(&cert, made.cert.pem()).unwrap();
    std::fs::write(&key, made.signing_key.serialize_pem()).unwrap();
    let env = [
        ("RACKD_SERVER__TLS__CERT_FILE", cert.to_str().unwrap()),
        ("RACKD_SERVER__TLS__KEY_FILE", key.to_str().unwrap()),
    ];
    let loaded = load(FILE, &env).unwrap();
    assert_eq!(loaded.config.server.tls, Some(TlsConfig::new(&cert, &key)));
    assert_eq!(loaded.origin("server.tls.key_file").to_string(), "env RACKD_SERVER__TLS__KEY_FILE");
    assert!(loaded.explain().contains("\n[server.tls]\ncert_file = "), "{}", loaded.explain());
    let swapped = [env[0], ("RACKD_SERVER__TLS__KEY_FILE", cert.to_str().unwrap())];
    let err = load(FILE, &swapped).unwrap_err().to_string();
    assert!(err.starts_with("env RACKD_SERVER__TLS__KEY_FILE: server.tls.key_file: "), "{err}");
    let err = load(FILE, &env[..1]).unwrap_err().to_string();
    assert!(err.contains("key_file"), "a certificate without its key: {err}");
}
