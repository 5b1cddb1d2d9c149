mod support;

use agp_plot::{PlotError, plot_gradient};

/// Checks that every tag is closed in order and the root is `<svg>`: XML enough for a
/// browser, without an XML crate.
fn assert_well_formed_svg(svg: &str) {
    let mut stack: Vec<String> = Vec::new();
    let mut rest = svg;
    let mut roots = 0;
    while let Some(start) = rest.find('<') {
        let after = &rest[start + 1..];
        let end = after.find('>').expect("every tag is closed by `>`");
        let tag = &after[..end];
        rest = &after[end + 1..];
        if tag.starts_with('?') || tag.starts_with('!') {
            continue;
        }
        if let Some(name) = tag.strip_prefix('/') {
            let open = stack.pop().expect("a closing tag has an opening tag");
            assert_eq!(open, name.trim(), "tags close in order");
        } else if !tag.ends_with('/') {
            let name = tag.split_whitespace().next().expect("a tag has a name");
            if stack.is_empty() {
                roots += 1;
                assert_eq!(name, "svg", "the root element is <svg>");
            }
            stack.push(name.to_owned());
        }
    }
    assert!(stack.is_empty(), "unclosed tags: {stack:?}");
    assert_eq!(roots, 1, "one root element");
}

fn title(name: &str, alpha: f64, pushes: u64) -> String {
    format!("{name}, α = {alpha}° ({pushes} pushes)")
}

#[test]
fn a_learned_disc_plots_as_one_svg_with_four_titled_panels_per_alpha() {
    let ag = support::learned_disc(24);
    let dir = tempfile::tempdir().expect("a temp dir");
    let path = dir.path().join("disc.svg");
    plot_gradient(&ag, "disc & friends", &path).expect("the plot is written");

    let svg = std::fs::read_to_string(&path).expect("the SVG is readable");
    assert!(svg.trim_start().starts_with("<svg"), "starts with <svg");
    assert_well_formed_svg(&svg);
    assert!(svg.contains("disc &amp; friends"), "the title is escaped");

    for alpha in [-15.0, 0.0, 15.0] {
        for name in ["S", "P", "R+", "R-"] {
            let t = title(name, alpha, 24);
            assert_eq!(svg.matches(&t).count(), 1, "one panel titled `{t}`");
        }
    }
    assert_eq!(svg.matches("R (deg)").count(), 3, "a colour bar per row");
    assert_eq!(svg.matches("x (mm)").count(), 12, "an x axis per panel");
}

#[test]
fn arrows_are_drawn_in_the_position_panels_only() {
    let ag = support::learned_disc(24);
    let dir = tempfile::tempdir().expect("a temp dir");
    let path = dir.path().join("disc.svg");
    plot_gradient(&ag, "disc", &path).expect("the plot is written");
    let svg = std::fs::read_to_string(&path).expect("the SVG is readable");

    // Panels are drawn in order S, P, R+, R-, each after its title: cut the SVG at titles.
    let mut cuts: Vec<(usize, String)> = Vec::new();
    for alpha in [-15.0, 0.0, 15.0] {
        for name in ["S", "P", "R+", "R-"] {
            let t = title(name, alpha, 24);
            let at = svg.find(&t).expect("the panel's title");
            cuts.push((at, name.to_owned()));
        }
    }
    cuts.sort();
    for (k, (at, name)) in cuts.iter().enumerate() {
        let end = cuts.get(k + 1).map_or(svg.len(), |c| c.0);
        let heads = svg[*at..end].matches("<polygon").count();
        if name == "P" {
            // 24 pushes round a 40 mm disc with 2.5 mm push sigma: a ring of predictions
            // about 16 mm wide; arrows every few cells on it.
            assert!(heads >= 20, "a P panel has arrows, found {heads}");
        } else {
            assert_eq!(heads, 0, "a {name} panel has no arrows");
        }
    }
}

#[test]
fn writing_leaves_only_the_svg_and_replaces_an_old_one() {
    let ag = support::learned_disc(12);
    let dir = tempfile::tempdir().expect("a temp dir");
    let path = dir.path().join("disc.svg");
    std::fs::write(&path, "old").expect("an old file");
    plot_gradient(&ag, "disc", &path).expect("the plot is written");
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .expect("the dir lists")
        .map(|e| e.expect("an entry").file_name())
        .collect();
    assert_eq!(names, ["disc.svg"], "no temporary file is left");
    let svg = std::fs::read_to_string(&path).expect("the SVG is readable");
    assert!(svg.contains("<svg"), "the old file is replaced");
}

#[test]
fn a_folder_that_does_not_exist_is_an_error_naming_the_path() {
    let ag = support::learned_disc(6);
    let dir = tempfile::tempdir().expect("a temp dir");
    let path = dir.path().join("no-such-folder").join("disc.svg");
    let err = plot_gradient(&ag, "disc", &path).expect_err("the folder does not exist");
    assert!(matches!(err, PlotError::Write { .. }), "{err:?}");
    let message = err.to_string();
    assert!(
        message.contains(&path.display().to_string()),
        "the message names the path: {message}"
    );
    assert!(!path.exists());
}

#[test]
fn a_gradient_without_pushes_still_plots() {
    let config = agp_affordance::LearnerConfig {
        alphas_deg: vec![0.0],
        ..Default::default()
    };
    let ag = agp_affordance::AffordanceLearner::new("nothing", &config)
        .expect("a valid config")
        .into_gradient();
    let dir = tempfile::tempdir().expect("a temp dir");
    let path = dir.path().join("empty.svg");
    plot_gradient(&ag, "empty", &path).expect("the plot is written");
    let svg = std::fs::read_to_string(&path).expect("the SVG is readable");
    assert_well_formed_svg(&svg);
    assert_eq!(
        svg.matches("<polygon").count(),
        0,
        "no arrows without pushes"
    );
}

#[test]
fn an_object_filling_the_grid_plots_in_a_bounded_file() {
    // A 120 mm disc: its S ring and pushes reach the grid's edges (128 cells of 2 mm), so
    // the heat maps show blocks of 2 x 2 cells (at most 80 blocks a side).
    let ag = support::learned_disc_of_radius(120, 0.12);
    let dir = tempfile::tempdir().expect("a temp dir");
    let path = dir.path().join("big.svg");
    plot_gradient(&ag, "big disc", &path).expect("the plot is written");
    let svg = std::fs::read_to_string(&path).expect("the SVG is readable");
    assert_well_formed_svg(&svg);
    assert!(svg.len() < 4_000_000, "the SVG is {} bytes", svg.len());
}
