//! Acceptance (issue 9): `magcal-fit --plots` writes its pictures for every recording from a physical sensor in
//! `../shared/data/real/`; each SVG parses and holds what it should: the readings (with the fitted outline), the
//! heading error, the residual against time with the located spans and found events, the orientation map with its
//! colour bar, units on the axes, and the legends in their strip above the data.

mod common;

use std::path::{Path, PathBuf};

use common::{magcal_fit, real};

/// The recordings (magcal-recording v1 files) in a folder of the shared data.
fn recordings(folder: &str) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(real(folder))
        .unwrap_or_else(|e| panic!("{folder}: {e}"))
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.extension().is_some_and(|e| e == "csv")
                && std::fs::read_to_string(p)
                    .unwrap()
                    .starts_with("# magcal-recording v1")
        })
        .collect();
    out.sort();
    assert!(!out.is_empty(), "no recordings in {folder}");
    out
}

/// The texts of an SVG with their `y`, and the count of each element name.
struct Svg {
    texts: Vec<(String, f64)>,
    circles: usize,
    rects: usize,
    lines: usize,
    fills: Vec<String>,
}

impl Svg {
    fn read(path: &Path) -> Svg {
        let text = std::fs::read_to_string(path).unwrap();
        let doc =
            roxmltree::Document::parse(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(doc.root_element().tag_name().name(), "svg");
        let count = |name: &str| {
            doc.descendants()
                .filter(|n| n.tag_name().name() == name)
                .count()
        };
        Svg {
            texts: doc
                .descendants()
                .filter(|n| n.tag_name().name() == "text")
                .map(|n| {
                    (
                        n.text().unwrap_or("").trim().to_owned(),
                        n.attribute("y").unwrap().parse().unwrap(),
                    )
                })
                .collect(),
            circles: count("circle"),
            rects: count("rect"),
            lines: count("polyline") + count("path"),
            fills: doc
                .descendants()
                .filter_map(|n| n.attribute("fill").map(str::to_owned))
                .collect(),
        }
    }

    fn has(&self, text: &str) -> bool {
        self.texts.iter().any(|(t, _)| t == text)
    }

    /// Every text starting with `label` lies in the legend strip at the top (two rows at most).
    fn in_legend_strip(&self, label: &str) -> bool {
        let found: Vec<f64> = self
            .texts
            .iter()
            .filter(|(t, _)| t.starts_with(label))
            .map(|(_, y)| *y)
            .collect();
        !found.is_empty() && found.iter().all(|y| *y < 54.0)
    }
}

fn check_folder(folder: &str) {
    for rec in recordings(folder) {
        let tmp = tempfile::tempdir().unwrap();
        let plots = tmp.path().join("plots");
        let report = tmp.path().join("report.json");
        let out = magcal_fit(&[
            rec.to_str().unwrap(),
            "--plots",
            plots.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
        ]);
        let dir = plots;
        let mut names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        let name = rec.display();
        let readings = Svg::read(&dir.join("readings.svg"));
        for axis in ["x (µT)", "y (µT)", "z (µT)"] {
            assert!(readings.has(axis), "{name}: no {axis}");
        }
        assert!(
            readings.circles > 500,
            "{name}: {} points",
            readings.circles
        );
        // The readings in their unit: µT, or raw units (the QMC5883L recordings: issue 34), said in the legend.
        let raw_units =
            String::from_utf8_lossy(&out.stdout).contains("the raw readings are not in µT");
        let unit = if raw_units { "raw units" } else { "µT" };
        assert!(
            readings.in_legend_strip(&format!("readings ({unit}, sensor axes)")),
            "{name}"
        );
        assert_eq!(readings.has("x (raw units)"), raw_units, "{name}");
        if !out.status.success() {
            // A refused fit: its raw readings are shown, and nothing else.
            assert_eq!(names, ["readings.svg"], "{name}");
            assert!(
                readings.has("raw readings only: the fit was refused"),
                "{name}"
            );
            continue;
        }
        let summary = String::from_utf8_lossy(&out.stdout);
        let report: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        let found = |id: &str| {
            report["diagnosis"]["effects"]
                .as_array()
                .is_some_and(|e| e.iter().any(|e| e["id"] == id))
        };
        // Three outlines of the ellipsoid and three circles of the sphere.
        assert!(readings.lines >= 6, "{name}: {} lines", readings.lines);
        assert!(
            readings.in_legend_strip("top: the fitted ellipsoid's outline"),
            "{name}"
        );
        for file in ["residual_time.svg", "residual_orientation.svg"] {
            assert!(names.iter().any(|n| n == file), "{name}: {names:?}");
        }
        let knows_heading = summary
            .lines()
            .nth(1)
            .unwrap()
            .starts_with("heading error, sensor level");
        assert_eq!(
            names.iter().any(|n| n == "heading.svg"),
            knows_heading,
            "{name}: {names:?}"
        );
        // Not written is said, with what would make it (issue 34): never silently.
        assert_eq!(
            String::from_utf8_lossy(&out.stderr).contains(
                "heading.svg not written: the heading error needs the local field's direction"
            ),
            !knows_heading,
            "{name}"
        );
        if knows_heading {
            let h = Svg::read(&dir.join("heading.svg"));
            for text in [
                "true heading (°)",
                "heading error (°)",
                "heading error left (°)",
            ] {
                assert!(h.has(text), "{name}: no {text}");
            }
            assert!(h.lines >= 4, "{name}: {} curves", h.lines);
            assert!(
                h.in_legend_strip("raw readings (top)") && h.in_legend_strip("dashed: z up"),
                "{name}"
            );
        }
        let t = Svg::read(&dir.join("residual_time.svg"));
        for text in ["t (s)", "residual RMS (µT)"] {
            assert!(t.has(text), "{name}: no {text}");
        }
        assert!(t.in_legend_strip("the sensor's noise"), "{name}");
        // The located spans are shaded, and named in the legend, exactly when the summary lists disturbances.
        let located = summary.contains("\n  disturbance ");
        assert_eq!(
            t.in_legend_strip("where the misfit was located"),
            located,
            "{name}"
        );
        assert_eq!(t.fills.iter().any(|f| f == "#FFBB78"), located, "{name}");
        for (event, id) in [
            ("offset step found", "bias_step"),
            ("disturbance found", "disturbance"),
        ] {
            assert_eq!(t.in_legend_strip(event), found(id), "{name}: {event}");
        }
        let o = Svg::read(&dir.join("residual_orientation.svg"));
        for text in [
            "around the sensor's z axis, from +x towards +y (°)",
            "up from the x–y plane towards +z (°)",
            "RMS (µT)",
            "(the noise)",
        ] {
            assert!(o.has(text), "{name}: no {text}");
        }
        // Cells the field never pointed through have a legend of their own (issue 34).
        assert!(
            o.in_legend_strip("the field never pointed this way: no readings"),
            "{name}"
        );
        // The map's cells and the colour bar's 40 steps.
        assert!(o.rects > 60, "{name}: {} rects", o.rects);
        if names.iter().any(|n| n == "residual_channel.svg") {
            let c = Svg::read(&dir.join("residual_channel.svg"));
            assert!(
                c.texts
                    .iter()
                    .any(|(t, _)| t.starts_with("residual ") && t.ends_with("(µT)")),
                "{name}"
            );
            assert!(c.in_legend_strip("the base fit (binned means)"), "{name}");
            // Every axis its right name and unit: the expected field's rate of change is µT/s, no gyro's rad/s.
            assert!(
                !c.has("rotation_rate (rad/s)")
                    && c.texts.iter().any(|(t, _)| t == "time (s)"
                        || t == "temperature (°C)"
                        || t == "the field's rate of change in sensor axes, |dB/dt| (µT/s)"
                        || t.starts_with("i_")),
                "{name}: {:?}",
                c.texts
            );
        }
    }
}

#[test]
fn plots_for_the_broad_recordings() {
    check_folder("broad");
}

#[test]
fn plots_for_the_hmc5883l_recordings() {
    check_folder("hmc5883l");
}

#[test]
fn plots_for_the_nexus5_recordings() {
    check_folder("inria-nexus5");
}

#[test]
fn plots_for_the_qmc5883l_recordings() {
    check_folder("qmc5883l");
}

/// `--plots` works without the diagnosis too: the fit's own residual is drawn.
#[test]
fn plots_without_the_diagnosis() {
    let dir = tempfile::tempdir().unwrap();
    let rec = real("inria-nexus5/nexus5_nodist_AR.csv");
    let out = magcal_fit(&[
        rec.to_str().unwrap(),
        "--no-diagnose",
        "--plots",
        dir.path().to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let t = Svg::read(&dir.path().join("residual_time.svg"));
    assert!(t.in_legend_strip("the fit") && !t.has("with the effects found"));
    assert!(dir.path().join("heading.svg").exists() && dir.path().join("readings.svg").exists());
    assert!(!dir.path().join("residual_channel.svg").exists());
}
