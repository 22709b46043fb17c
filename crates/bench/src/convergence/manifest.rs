//! `views.csv` in the output folder: which views were measured and on what terms. Views can be
//! measured one at a time (the full benchmark is long on two cores); each new measurement replaces
//! that view's line (a view under each profile has its own), and the Markdown section and
//! `bench accuracy` cover every line.

use std::path::Path;

use anyhow::Context;
use sma::config::Profile;

const FILE: &str = "views.csv";
const HEADER: &str =
    "label,scene,view,width,height,gt_spp,seconds,sample_counts,ground_truth,measured,profile";

/// One measured view and its terms.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewRecord {
    /// The scene's name, used in file names (`bracara`, `sponza`).
    pub label: String,
    /// The scene as given on the command line (a TOML path or a built-in name).
    pub scene: String,
    pub view: String,
    pub width: u32,
    pub height: u32,
    pub gt_spp: u32,
    pub seconds: f64,
    /// The viewer's `--snapshot-at-samples` list.
    pub sample_counts: Vec<u64>,
    /// The ground truth EXR (in the ignored cache folder).
    pub ground_truth: String,
    /// When and at which commit the runs were made (`machine::measured_stamp`); empty in a line
    /// written before the column existed.
    pub measured: String,
    /// Which system ran (the SMA's `--profile`); today's in a line written before the column
    /// existed.
    pub profile: Profile,
}

impl ViewRecord {
    /// `<label>-<view>`, and `-<profile>` past today's: the stem of this view's files.
    pub fn stem(&self) -> String {
        match self.profile {
            Profile::Today => self.view_stem(),
            profile => format!("{}-{}", self.view_stem(), profile.name()),
        }
    }

    /// `<label>-<view>`, whatever the profile: what the view's ground truth and direct render
    /// are known by.
    pub fn view_stem(&self) -> String {
        format!("{}-{}", self.label, self.view)
    }

    /// `<label> <view>, <profile label>`: how headings and plot titles name the measurement.
    pub fn title(&self) -> String {
        format!("{} {}, {}", self.label, self.view, self.profile.label())
    }

    fn line(&self) -> String {
        let r = self;
        let counts: Vec<String> = r.sample_counts.iter().map(u64::to_string).collect();
        let (width, height, spp, seconds) = (r.width, r.height, r.gt_spp, r.seconds);
        format!(
            "{},{},{},{width},{height},{spp},{seconds},{},{},{},{}",
            r.label,
            r.scene,
            r.view,
            counts.join(";"),
            r.ground_truth,
            r.measured,
            r.profile.name()
        )
    }

    fn parse(line: &str) -> anyhow::Result<ViewRecord> {
        let f: Vec<&str> = line.split(',').collect();
        anyhow::ensure!(
            (9..=11).contains(&f.len()),
            "expected 11 fields (9 before `measured`, 10 before `profile`)"
        );
        let profile = match f.get(10) {
            None => Profile::Today,
            Some(name) => {
                Profile::from_name(name).with_context(|| format!("no profile is named {name:?}"))?
            }
        };
        Ok(ViewRecord {
            label: f[0].into(),
            scene: f[1].into(),
            view: f[2].into(),
            width: f[3].parse()?,
            height: f[4].parse()?,
            gt_spp: f[5].parse()?,
            seconds: f[6].parse()?,
            sample_counts: f[7]
                .split(';')
                .filter(|s| !s.is_empty())
                .map(str::parse)
                .collect::<Result<_, _>>()?,
            ground_truth: f[8].into(),
            measured: f.get(9).copied().unwrap_or("").into(),
            profile,
        })
    }
}

pub fn read(dir: &Path) -> anyhow::Result<Vec<ViewRecord>> {
    let path = dir.join(FILE);
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("reading {} (run `bench convergence` first)", path.display()))?;
    text.lines()
        .skip(1)
        .filter(|l| !l.is_empty())
        .map(|l| ViewRecord::parse(l).with_context(|| format!("{}: {l:?}", path.display())))
        .collect()
}

/// Adds or replaces `record`'s line, keeping the others in their order.
pub fn upsert(dir: &Path, record: &ViewRecord) -> anyhow::Result<()> {
    let mut records = read(dir).unwrap_or_default();
    match records.iter_mut().find(|r| r.stem() == record.stem()) {
        Some(old) => *old = record.clone(),
        None => records.push(record.clone()),
    }
    let lines: Vec<String> = std::iter::once(HEADER.to_string())
        .chain(records.iter().map(ViewRecord::line))
        .collect();
    std::fs::write(dir.join(FILE), lines.join("\n") + "\n")?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(view: &str, seconds: f64) -> ViewRecord {
        ViewRecord {
            label: "bracara".into(),
            scene: "bracara".into(),
            view: view.into(),
            width: 320,
            height: 240,
            gt_spp: 256,
            seconds,
            sample_counts: vec![1000, 2000],
            ground_truth: "out/gt/x.exr".into(),
            measured: "2026-12-04 at abc1234".into(),
            profile: Profile::Today,
        }
    }

    #[test]
    fn lines_from_before_the_measured_and_profile_columns_still_read() {
        let mut r = record("MC", 5.0);
        let line = r.line();
        let before_profile = line.rsplit_once(',').unwrap().0;
        assert_eq!(ViewRecord::parse(before_profile).unwrap(), r);
        let before_measured = before_profile.rsplit_once(',').unwrap().0;
        r.measured.clear();
        assert_eq!(ViewRecord::parse(before_measured).unwrap(), r);
    }

    #[test]
    fn a_view_under_each_profile_has_its_own_line_and_files() {
        let dir = tempfile::tempdir().unwrap();
        let thesis = ViewRecord {
            profile: Profile::Thesis,
            ..record("MC", 5.0)
        };
        assert_eq!(thesis.stem(), "bracara-MC-thesis");
        assert_eq!(thesis.view_stem(), record("MC", 5.0).stem());
        assert_eq!(thesis.title(), "bracara MC, thesis (2006)");
        upsert(dir.path(), &record("MC", 5.0)).unwrap();
        upsert(dir.path(), &thesis).unwrap();
        assert_eq!(read(dir.path()).unwrap(), vec![record("MC", 5.0), thesis]);
    }

    #[test]
    fn upsert_replaces_a_view_and_keeps_the_others() {
        let dir = tempfile::tempdir().unwrap();
        upsert(dir.path(), &record("MC", 5.0)).unwrap();
        upsert(dir.path(), &record("VT", 5.0)).unwrap();
        upsert(dir.path(), &record("MC", 20.0)).unwrap();
        assert_eq!(
            read(dir.path()).unwrap(),
            vec![record("MC", 20.0), record("VT", 5.0)]
        );
    }
}
