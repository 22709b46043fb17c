//! The SMA's command line: flags, defaults and the profile's settings.

use super::*;

#[test]
fn flag_defaults_are_the_config_defaults() {
    let cli = Cli::try_parse_from(["sma", "--renderer", "r:1"]).unwrap();
    let (from_flags, defaults) = (cli.config().unwrap(), SmaConfig::default());
    assert_eq!(from_flags.listen, defaults.listen);
    assert_eq!(from_flags.renderers, ["r:1"]);
    assert_eq!(from_flags.max_frame, defaults.max_frame);
    assert_eq!(from_flags.liveness, defaults.liveness);
    assert_eq!(from_flags.renderer_port, defaults.renderer_port);
    assert_eq!(from_flags.deadline_factor, defaults.deadline_factor);
    assert_eq!(from_flags.first_deadline, defaults.first_deadline);
    assert_eq!(from_flags.viewer_silence, defaults.viewer_silence);
    assert_eq!(
        from_flags.viewer_backlog_bytes,
        defaults.viewer_backlog_bytes
    );
    assert_eq!(
        format!("{:?}", from_flags.schedule),
        format!("{:?}", defaults.schedule)
    );
    assert_eq!(
        format!("{:?}", from_flags.mesh),
        format!("{:?}", defaults.mesh)
    );
}

#[test]
fn the_memory_budget_is_given_in_mib_fractions_allowed() {
    let budget = |mib: &str| {
        let cli = Cli::try_parse_from(["sma", "--renderer", "r:1", "--memory-mib", mib]).unwrap();
        cli.config().unwrap().schedule.memory_budget_bytes
    };
    assert_eq!(budget("64"), 64 << 20);
    assert_eq!(budget("0.5"), 1 << 19);
    assert!(Cli::try_parse_from(["sma", "--renderer", "r:1", "--cache-mib", "64"]).is_err());
}

#[test]
fn renderers_are_dialed_or_join_a_renderer_port_but_one_way_is_given() {
    let cli = Cli::try_parse_from(["sma", "--renderer-listen", "0.0.0.0:7300"]).unwrap();
    let config = cli.config().unwrap();
    assert_eq!(config.renderer_listen.as_deref(), Some("0.0.0.0:7300"));
    assert!(config.renderers.is_empty());
    assert!(Cli::try_parse_from(["sma"]).is_err());
}

#[test]
fn criteria_are_parsed_by_name() {
    let cli = Cli::try_parse_from(["sma", "--renderer", "r:1", "--criterion", "rnd"]).unwrap();
    assert_eq!(cli.criterion, Some(CriterionKind::Rnd));
    assert!(Cli::try_parse_from(["sma", "--renderer", "r:1", "--criterion", "x"]).is_err());
    let cli = Cli::try_parse_from(["sma", "--renderer", "r:1", "--criterion", "nld-mm"]).unwrap();
    assert_eq!(cli.criterion, Some(CriterionKind::NldMm));
    let default = Cli::try_parse_from(["sma", "--renderer", "r:1"]).unwrap();
    assert_eq!(
        default.config().unwrap().schedule.criterion,
        CriterionKind::NldPx
    );
}

#[test]
fn the_neighbour_rule_is_parsed_by_name() {
    let with = |rule: &str| {
        Cli::try_parse_from(["sma", "--renderer", "r:1", "--neighbour-rule", rule])
            .map(|cli| cli.config().unwrap().mesh.neighbour_rule)
    };
    assert_eq!(with("thesis").unwrap(), NeighbourRule::Thesis);
    assert_eq!(with("red-green").unwrap(), NeighbourRule::RedGreen);
    assert!(with("loop").is_err());
    let default = Cli::try_parse_from(["sma", "--renderer", "r:1"]).unwrap();
    assert_eq!(
        default.config().unwrap().mesh.neighbour_rule,
        NeighbourRule::RedGreen
    );
}

#[test]
fn merging_by_uniformity_is_switched_on_or_off() {
    let with = |value: &str| {
        Cli::try_parse_from(["sma", "--renderer", "r:1", "--merge-uniform", value])
            .map(|cli| cli.config().unwrap().schedule.merge_uniform)
    };
    assert!(with("on").unwrap());
    assert!(!with("off").unwrap());
    assert!(with("yes").is_err());
    let default = Cli::try_parse_from(["sma", "--renderer", "r:1"]).unwrap();
    assert!(
        !default.config().unwrap().schedule.merge_uniform,
        "off until measured"
    );
}

#[test]
fn a_round_share_outside_zero_to_one_is_refused() {
    let with =
        |share: &str| Cli::try_parse_from(["sma", "--renderer", "r:1", "--round-share", share]);
    assert_eq!(
        with("0.25").unwrap().config().unwrap().schedule.round_share,
        0.25
    );
    for bad in ["0", "-0.1", "1.5", "NaN", "x"] {
        assert!(with(bad).is_err(), "{bad} accepted");
    }
}

fn thesis(flags: &[&str]) -> anyhow::Result<SmaConfig> {
    let args = ["sma", "--renderer", "r:1", "--profile", "thesis"];
    Cli::try_parse_from(args.iter().chain(flags))?.config()
}

#[test]
fn the_thesis_profile_is_the_config_with_that_profile() {
    let config = thesis(&[]).unwrap();
    let want = SmaConfig::of_profile(Profile::Thesis);
    assert_eq!(config.schedule.profile, Profile::Thesis);
    assert_eq!(config.schedule.criterion, CriterionKind::NldOsThesis);
    assert_eq!(
        format!("{:?}", config.schedule),
        format!("{:?}", want.schedule)
    );
    assert_eq!(format!("{:?}", config.mesh), format!("{:?}", want.mesh));
    assert!(Cli::try_parse_from(["sma", "--renderer", "r:1", "--profile", "x"]).is_err());
}

#[test]
fn the_thesis_profile_maps_the_noise_aware_criteria_and_refuses_nld_px() {
    let criterion = |name| thesis(&["--criterion", name]).map(|c| c.schedule.criterion);
    assert_eq!(criterion("nld-is").unwrap(), CriterionKind::NldIsThesis);
    assert_eq!(criterion("rnd").unwrap(), CriterionKind::Rnd);
    assert_eq!(criterion("nld-mm").unwrap(), CriterionKind::NldMm);
    let refused = criterion("nld-px").unwrap_err().to_string();
    assert!(
        refused.contains("nld-px") && refused.contains("thesis (2006)"),
        "{refused}"
    );
}

#[test]
fn a_flag_given_beside_the_profile_still_wins() {
    let config = thesis(&[
        "--neighbour-rule",
        "red-green",
        "--l-white-outliers",
        "0.01",
        "--coarsen-after-passes",
        "5",
    ])
    .unwrap();
    assert_eq!(config.mesh.neighbour_rule, NeighbourRule::RedGreen);
    assert_eq!(config.schedule.l_white_outliers, 0.01);
    assert_eq!(config.schedule.coarsen_after_passes, 5);
    assert!(!config.schedule.ladder, "the rest is the thesis's");
    assert!(thesis(&["--l-white-outliers", "1"]).is_err());
}

#[test]
fn work_while_walking_is_on_today_off_under_the_thesis_and_a_flag_sets_it() {
    let flag = |v| ["sma", "--renderer", "r:1", "--work-while-walking", v];
    let walks = |c: anyhow::Result<SmaConfig>| c.unwrap().schedule.work_while_walking;
    assert!(walks(
        Cli::try_parse_from(["sma", "--renderer", "r:1"])
            .unwrap()
            .config()
    ));
    assert!(!walks(Cli::try_parse_from(flag("off")).unwrap().config()));
    assert!(Cli::try_parse_from(flag("yes")).is_err());
    assert!(!walks(thesis(&[])) && walks(thesis(&["--work-while-walking", "on"])));
}

#[test]
fn a_walking_cameras_passes_lead_it_today_not_under_the_thesis_and_as_flagged() {
    let leads = |args: &[&str]| {
        let mut all = vec!["sma", "--renderer", "r:1"];
        all.extend_from_slice(args);
        Cli::try_parse_from(all).map(|cli| cli.config().unwrap().schedule.lead_while_walking)
    };
    assert!(leads(&[]).unwrap());
    assert!(!leads(&["--lead-while-walking", "off"]).unwrap());
    assert!(leads(&["--lead-while-walking", "maybe"]).is_err());
    assert!(!thesis(&[]).unwrap().schedule.lead_while_walking);
}

#[test]
fn a_walking_viewer_keeps_what_left_its_view_two_seconds_none_under_the_thesis_or_as_flagged() {
    let kept = |args: &[&str]| {
        let mut all = vec!["sma", "--renderer", "r:1"];
        all.extend_from_slice(args);
        Cli::try_parse_from(all).map(|cli| cli.config().unwrap().schedule.kept_while_walking)
    };
    assert_eq!(kept(&[]).unwrap(), Duration::from_secs(2));
    assert_eq!(
        kept(&["--kept-while-walking-s", "0.5"]).unwrap(),
        Duration::from_millis(500)
    );
    for bad in ["-1", "NaN", "inf", "4000"] {
        assert!(kept(&["--kept-while-walking-s", bad]).is_err(), "{bad}");
    }
    assert_eq!(
        thesis(&[]).unwrap().schedule.kept_while_walking,
        Duration::ZERO
    );
    assert_eq!(
        thesis(&["--kept-while-walking-s", "1"])
            .unwrap()
            .schedule
            .kept_while_walking,
        Duration::from_secs(1)
    );
}

#[test]
fn the_indirect_filter_is_on_by_default_off_under_the_thesis_profile_and_by_flag() {
    let parsed = |args: &[&str]| {
        let mut all = vec!["sma", "--renderer", "r:1"];
        all.extend_from_slice(args);
        Cli::try_parse_from(all).map(|cli| cli.config().unwrap().schedule.indirect_filter.enabled)
    };
    assert!(parsed(&[]).unwrap());
    assert!(!parsed(&["--indirect-filter", "off"]).unwrap());
    assert!(parsed(&["--indirect-filter", "on"]).unwrap());
    assert!(parsed(&["--indirect-filter", "maybe"]).is_err());
    assert!(!parsed(&["--profile", "thesis", "--criterion", "nld-os"]).unwrap());
    let radius = |value: &str| {
        Cli::try_parse_from([
            "sma",
            "--renderer",
            "r:1",
            "--indirect-filter-radius",
            value,
        ])
        .map(|cli| cli.config().unwrap().schedule.indirect_filter.radius)
    };
    assert_eq!(radius("0.003").unwrap(), 0.003);
    assert!(radius("1.5").is_err());
}

#[test]
fn a_cache_file_is_used_only_when_asked_for_and_never_under_the_thesis_profile() {
    let config = |args: &[&str]| {
        let base = ["sma", "--renderer", "r:1"].into_iter();
        Cli::try_parse_from(base.chain(args.iter().copied()))
            .unwrap()
            .config()
            .unwrap()
            .cache_file
    };
    assert_eq!(config(&[]), None);
    let file = config(&["--cache-file", "/c/site.redb", "--cache-file-save-s", "2"]).unwrap();
    assert_eq!(file.location, Location::File(PathBuf::from("/c/site.redb")));
    assert_eq!(file.save_every, Duration::from_secs(2));
    let per_scene = config(&["--cache-dir", "/c"]).unwrap();
    assert_eq!(per_scene.location, Location::PerScene(PathBuf::from("/c")));
    assert_eq!(per_scene.save_every, CacheFileConfig::SAVE_EVERY);
    assert_eq!(config(&["--cache-dir", "/c", "--profile", "thesis"]), None);
    assert!(
        Cli::try_parse_from([
            "sma",
            "--renderer",
            "r:1",
            "--cache-file",
            "a",
            "--cache-dir",
            "b"
        ])
        .is_err()
    );
}
