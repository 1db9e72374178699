//! Writes the Autodig map figures of docs/autodig.md (thesis Figs. 10-11) from the shipped maps
//! (`config/autodig_maps.toml`): `cargo run -p lab --example autodig_maps -- docs` (default folder:
//! the current one).

fn main() -> anyhow::Result<()> {
    let dir = std::env::args_os()
        .nth(1)
        .map_or_else(|| std::path::PathBuf::from("."), std::path::PathBuf::from);
    std::fs::create_dir_all(&dir)?;
    let maps = planner::autodig::AutodigMaps::builtin()?;
    for path in lab::autodig_maps_svg::write_map_svgs(&maps, &dir)? {
        println!("{}", path.display());
    }
    Ok(())
}
