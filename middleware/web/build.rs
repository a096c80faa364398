//! The front end is embedded from `ui/dist`: rebuild when Vite writes it anew (its asset
//! names change with their content, so a new build is a new set of files).
fn main() {
    println!("cargo:rerun-if-changed=ui/dist");
}
