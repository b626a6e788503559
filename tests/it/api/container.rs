//! The container files (Dockerfile, compose.yaml, config/container.toml, .dockerignore) read
//! and checked for the properties a site relies on, so that they cannot regress silently.
//! Building the image compiles rackd in release, far too slow for every CI run;
//! docs/operations/container.md records the end-to-end run with podman.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use rackd::config::Config;
use yaml_rust2::{Yaml, YamlLoader};

/// A file of the repository.
fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

fn read(path: &str) -> String {
    std::fs::read_to_string(repo(path)).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// One Dockerfile instruction: its keyword (upper case) and the rest of its line, with
/// continuation lines joined.
#[derive(Debug)]
struct Instruction {
    keyword: String,
    args: String,
}

/// The Dockerfile's instructions, in order, grouped by stage: the instructions before the
/// first FROM (global ARGs) come first, then each FROM with what follows it.
fn dockerfile() -> Vec<Vec<Instruction>> {
    let text = read("Dockerfile");
    let mut stages = vec![Vec::new()];
    let mut line = String::new();
    for raw in text.lines() {
        let trimmed = raw.trim();
        if trimmed.starts_with('#') || (trimmed.is_empty() && line.is_empty()) {
            continue;
        }
        match trimmed.strip_suffix('\\') {
            Some(part) => {
                line.push_str(part);
                line.push(' ');
            }
            None => {
                line.push_str(trimmed);
                let (keyword, args) = line.split_once(char::is_whitespace).unwrap_or((&line, ""));
                let instruction =
                    Instruction { keyword: keyword.to_ascii_uppercase(), args: args.trim().to_owned() };
                if instruction.keyword == "FROM" {
                    stages.push(Vec::new());
                }
                stages.last_mut().unwrap().push(instruction);
                line.clear();
            }
        }
    }
    assert!(line.is_empty(), "the Dockerfile ends in a continuation: {line}");
    stages
}

/// The JSON (exec) form of an instruction's arguments.
fn exec_form(args: &str) -> Vec<String> {
    serde_json::from_str(args).unwrap_or_else(|e| panic!("not the exec form ({e}): {args}"))
}

/// Whether `image` names a version tag (not `latest`, not a bare major) and a digest.
fn pinned(image: &str) -> bool {
    let Some((name, digest)) = image.split_once("@sha256:") else { return false };
    let tag = name.rsplit_once(':').map(|(_, t)| t).unwrap_or("");
    let version = tag.split('-').next().unwrap_or("");
    let exact =
        version.matches('.').count() >= 2 || tag.split('-').any(|p| p.len() == 8 && p.parse::<u32>().is_ok());
    digest.len() == 64 && digest.chars().all(|c| c.is_ascii_hexdigit()) && tag != "latest" && exact
}

#[test]
fn base_images_are_pinned_by_tag_and_digest_and_overridable() {
    let stages = dockerfile();
    let args: HashMap<&str, &str> =
        stages[0].iter().filter(|i| i.keyword == "ARG").filter_map(|i| i.args.split_once('=')).collect();
    let froms: Vec<&str> = stages[1..].iter().map(|s| s[0].args.split_whitespace().next().unwrap()).collect();
    assert_eq!(froms.len(), 2, "a build stage and a runtime stage: {froms:?}");
    for from in froms {
        let arg = from.strip_prefix("${").and_then(|f| f.strip_suffix('}'));
        let arg = arg.unwrap_or_else(|| {
            panic!("FROM {from}: the base comes from an ARG, to build without Docker Hub")
        });
        let default = args.get(arg).unwrap_or_else(|| panic!("ARG {arg} has a default"));
        assert!(pinned(default), "{arg}={default} is pinned by a version tag and a digest");
        assert!(default.starts_with("docker.io/library/"), "{default}: the official image, fully named");
    }
    assert!(!pinned(&format!("docker.io/library/rust:1-bookworm@sha256:{}", "0".repeat(64))));
    assert!(!pinned("debian:bookworm-slim"));
}

#[test]
fn no_image_environment_overrides_the_configuration() {
    for stage in dockerfile() {
        for i in stage.iter().filter(|i| i.keyword == "ENV") {
            assert!(!i.args.contains("RACKD_"), "ENV {}: configuration comes from the mounted file", i.args);
        }
    }
}

#[test]
fn the_runtime_stage_runs_as_10001_in_dialout_with_a_health_check_and_the_default_config() {
    let stages = dockerfile();
    let runtime = stages.last().unwrap();
    let one = |keyword: &str| -> &str {
        let found: Vec<&Instruction> = runtime.iter().filter(|i| i.keyword == keyword).collect();
        assert_eq!(found.len(), 1, "one {keyword} in the runtime stage");
        &found[0].args
    };
    assert!(matches!(one("USER"), "10001:dialout" | "10001:20"), "USER {}", one("USER"));
    let useradd = runtime.iter().find(|i| i.keyword == "RUN" && i.args.contains("useradd")).expect("useradd");
    assert!(
        useradd.args.contains("--uid 10001") && useradd.args.contains("--gid dialout"),
        "{}",
        useradd.args
    );
    assert!(useradd.args.contains("chown 10001"), "the /data volume belongs to rackd: {}", useradd.args);
    assert_eq!(exec_form(one("ENTRYPOINT")), ["rackd"]);
    assert_eq!(exec_form(one("CMD")), ["serve", "--config", "/etc/rackd/rackd.toml"]);
    assert!(
        runtime
            .iter()
            .any(|i| i.keyword == "COPY" && i.args == "config/container.toml /etc/rackd/rackd.toml"),
        "the default configuration is in the image"
    );
    assert_eq!(exec_form(one("VOLUME")), ["/data"]);

    let health = one("HEALTHCHECK");
    let command = exec_form(health.split_once("CMD").expect("HEALTHCHECK ... CMD [...]").1.trim());
    assert_eq!(command[..2], ["rackd", "healthcheck"]);
    let url = &command[command.iter().position(|a| a == "--url").expect("--url") + 1];
    let port = container_config().server.listen.port();
    assert_eq!(url, &format!("http://127.0.0.1:{port}/healthz"), "the check asks the configured port");
    assert_eq!(one("EXPOSE"), port.to_string());
}

#[test]
fn dependencies_build_in_their_own_layer_before_the_sources_arrive() {
    let stages = dockerfile();
    let build = &stages[1];
    let at = |pred: &dyn Fn(&Instruction) -> bool, what: &str| {
        build.iter().position(pred).unwrap_or_else(|| panic!("{what} in the build stage"))
    };
    let manifests =
        at(&|i| i.keyword == "COPY" && i.args == "Cargo.toml Cargo.lock ./", "COPY Cargo.toml Cargo.lock");
    let deps = at(
        &|i| i.keyword == "RUN" && i.args.contains("cargo build --release --locked"),
        "a dependency build",
    );
    let sources = at(&|i| i.keyword == "COPY" && i.args.starts_with("src "), "COPY src");
    assert!(manifests < deps && deps < sources, "manifests, then dependencies, then sources");
    // The shared build settings (SQLite's compile flags) reach the dependencies' build.
    let settings = at(&|i| i.keyword == "COPY" && i.args == ".cargo .cargo", "COPY .cargo");
    assert!(settings < deps, "build settings before the dependency build");
    assert!(read(".cargo/config.toml").contains("LIBSQLITE3_FLAGS"));
    let ignored = read(".dockerignore");
    for entry in ["target/", ".git/"] {
        assert!(ignored.lines().any(|l| l.trim() == entry), ".dockerignore has {entry}");
    }
    assert!(
        !ignored.lines().any(|l| l.trim().trim_end_matches('/') == ".cargo"),
        ".dockerignore keeps .cargo"
    );
}

/// config/container.toml, loaded as rackd loads it.
fn container_config() -> Config {
    Config::load(&repo("config/container.toml")).expect("config/container.toml loads")
}

#[test]
fn the_shipped_config_serves_all_interfaces_from_the_volume_and_carries_no_key() {
    let config = container_config();
    assert!(config.server.listen.ip().is_unspecified(), "{}", config.server.listen);
    assert_eq!(config.database.path, Path::new("/data/rackd.db"));
    assert!(config.auth.keys.is_empty(), "no API key is baked into the image");
    assert!(config.devices.is_empty(), "the image knows no site's machines");
}

#[tokio::test]
async fn the_shipped_config_alone_refuses_to_serve_without_keys() {
    // Loaded as the image loads it, bound to a test port: the refusal comes from the
    // configured 0.0.0.0 and the missing keys, before anything opens.
    let mut config = container_config();
    let dir = tempfile::tempdir().unwrap();
    config.database.path = dir.path().join("rackd.db");
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let err = match rackd::app::Application::build_on(&config, listener, false).await {
        Ok(_) => panic!("an open WCS on 0.0.0.0"),
        Err(e) => e.to_string(),
    };
    assert!(err.contains("[[auth.keys]]") && err.contains("--insecure"), "{err}");
    assert!(!config.database.path.exists(), "refused before the database opened");
}

fn compose_service() -> (Yaml, Yaml) {
    let docs = YamlLoader::load_from_str(&read("compose.yaml")).expect("compose.yaml is YAML");
    let doc = docs.into_iter().next().expect("one document");
    let service = doc["services"]["rackd"].clone();
    assert!(!service.is_badvalue(), "services.rackd");
    (doc, service)
}

fn strings(list: &Yaml) -> Vec<&str> {
    list.as_vec().map(|v| v.iter().filter_map(Yaml::as_str).collect()).unwrap_or_default()
}

#[test]
fn compose_keeps_data_in_a_named_volume_and_mounts_the_config_read_only() {
    let (doc, service) = compose_service();
    let volumes = strings(&service["volumes"]);
    let data = volumes.iter().find(|v| v.ends_with(":/data")).expect("a volume on /data");
    let name = data.trim_end_matches(":/data");
    assert!(!name.starts_with(['.', '/']), "{data}: a named volume, which the image prepares for uid 10001");
    assert!(
        doc["volumes"].as_hash().is_some_and(|h| h.contains_key(&Yaml::String(name.into()))),
        "volume {name}"
    );
    assert!(
        volumes.iter().any(|v| v.ends_with(":/etc/rackd/rackd.toml:ro")),
        "the config, read-only: {volumes:?}"
    );
    assert!(matches!(service["restart"].as_str(), Some("unless-stopped" | "always")), "a restart policy");
    assert!(service["environment"].is_badvalue(), "no environment overriding the config");
}

#[test]
fn compose_checks_health_and_shows_a_serial_port() {
    let (_, service) = compose_service();
    let test = strings(&service["healthcheck"]["test"]);
    let port = container_config().server.listen.port();
    let url = format!("http://127.0.0.1:{port}/healthz");
    assert_eq!(test, ["CMD", "rackd", "healthcheck", "--url", url.as_str()]);
    assert_eq!(strings(&service["group_add"]), ["dialout"]);
    let text = read("compose.yaml");
    assert!(text.contains("# devices:") && text.contains("/dev/ttyUSB0:/dev/ttyUSB0"), "the serial example");
}

#[test]
fn compose_runs_read_only_without_capabilities_or_new_privileges() {
    let (_, service) = compose_service();
    assert_eq!(service["read_only"].as_bool(), Some(true), "a read-only root");
    assert_eq!(strings(&service["cap_drop"]), ["ALL"], "no capabilities");
    assert!(strings(&service["security_opt"]).contains(&"no-new-privileges:true"), "no new privileges");
    // rackd writes nothing outside /data (SQLite keeps its temporary tables in memory:
    // libsqlite3-sys builds it with SQLITE_TEMP_STORE=2), so no tmpfs is needed.
    assert!(service["tmpfs"].is_badvalue(), "a tmpfs nobody writes to");
}

#[test]
fn compose_publishes_on_loopback_and_takes_the_database_url_from_a_secret_file() {
    let (_, service) = compose_service();
    let port = container_config().server.listen.port();
    assert_eq!(strings(&service["ports"]), [format!("127.0.0.1:{port}:{port}").as_str()], "loopback only");
    let text = read("compose.yaml");
    assert!(
        text.contains("[server.tls]") && text.contains(&format!("\"{port}:{port}\"")),
        "how to publish with TLS"
    );
    // PostgreSQL is optional: the example names the URL's secret file, never a variable.
    for line in
        ["#   url_file = \"/run/secrets/database_url\"", "#   - database_url", "#     file: ./database_url"]
    {
        assert!(text.contains(line), "{line}");
    }
    assert!(!text.contains("RACKD_DATABASE__URL"), "no database URL in the environment");
}
