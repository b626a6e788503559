//! What the page shows of a reload: the running configuration's hash and load time in the
//! header, a new aisle drawn with its locations, a removed device gone from the devices,
//! as the `config.reloaded` event comes (no page reload).

use rackd::cli::demo;
use rackd::config::Config;
use rackd::store::Database;

use super::{Browser, FAST};
use crate::support::{spawn_from_file_on, split};

#[tokio::test]
async fn the_page_follows_a_reload() {
    let Some(browser) = Browser::start().await else { return };
    let mut config = Config::demo();
    let _sims = demo::start_with(&mut config, FAST).await.expect("demo simulators start");
    let dir = tempfile::tempdir().unwrap();
    let db = Database::Sqlite(dir.path().join("rackd.db"));
    let (app, file) = spawn_from_file_on(db, config, dir).await;
    browser.viewport(1600, 1000).await;
    browser.open(&app.url("/")).await;
    browser.live().await;
    let hash = app.get("/api/v1/config").await.1["hash"].as_str().unwrap().to_owned();
    let shown = browser
        .wait(
            "the configuration's hash",
            "const c = document.querySelector('#config'); \
        return c && !c.hidden && c.textContent",
            10,
        )
        .await;
    assert!(shown.as_str().unwrap().contains(&hash[..8]), "{shown}");
    let towers =
        "return [...document.querySelectorAll('#devices .device')].map((d) => d.dataset.device).join(',')";
    browser
        .wait(
            "the tower listed",
            &format!("const ids = (() => {{ {towers} }})(); return ids.includes('tower1') && ids"),
            10,
        )
        .await;

    // A third aisle, and the tower removed.
    let mut new = Config::load(&file).unwrap();
    let mut third = new.site.aisles[0].clone();
    third.aisle = 3;
    new.site.aisles.push(third);
    new.devices.retain(|d| d.id() != "tower1");
    std::fs::write(&file, toml::to_string(&new).unwrap()).unwrap();
    let post = app.client.post(app.url("/api/v1/config/reload")).header("content-type", "application/json");
    let (status, body) = split(post.send().await.unwrap()).await;
    assert_eq!(status, 200, "{body}");
    let hash = body["hash"].as_str().unwrap();
    let script = format!(
        "const c = document.querySelector('#config'); return c.textContent.includes('{}') && c.textContent",
        &hash[..8]
    );
    browser.wait("the new hash", &script, 10).await;
    let aisles = "return window.rackd.model.locations.size > 0 && \
        [...window.rackd.model.locations.values()].some((l) => l.aisle === 3)";
    browser.wait("the new aisle's locations", aisles, 10).await;
    let gone = format!("const ids = (() => {{ {towers} }})(); return !ids.includes('tower1') && ids");
    browser.wait("the tower gone", &gone, 10).await;
    app.stop().await;
}
