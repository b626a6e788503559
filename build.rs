//! The build script: rebuilds when a migration is added (they are compiled in).

fn main() {
    // The migrations are compiled in (sqlx::migrate!): a new file must rebuild the crate.
    println!("cargo:rerun-if-changed=migrations");
}
