//! Eviction to the cache file under the memory budget (`cache_file::evict`): a subtree no view
//! sees is written, dropped, and comes back from the file as it was; one whose save fails stays.

use super::*;

/// What `shown` holds of the leaves whose corners all lie in x ≥ 4.5: the far area.
fn far_part(shown: &Shown) -> Shown {
    shown
        .iter()
        .filter(|(corners, _)| corners.iter().all(|c| f32::from_bits(c[0]) >= 4.5))
        .map(|(c, s)| (c.clone(), s.clone()))
        .collect()
}

/// A file with a near and a far area refined and shaded, the far one changed again since the
/// last commit (so leaving must write it first).
fn refined_site(config: &Config) -> (SubdivisionMesh, ShadingCache, CacheFile) {
    let (mut mesh, mut cache) = fresh();
    let mut file = CacheFile::open(&config.path, config.save_every, &key(), &mesh).unwrap();
    refine_area(&mut mesh, 0.0, 1.5);
    refine_area(&mut mesh, 4.5, 6.0);
    shade(&mesh, &mut cache);
    file.samples_changed(0..mesh.vertex_count() as u32);
    file.save_now(&mut mesh, &cache);
    let far = bases_in(&mesh, 4.5, 6.0);
    let leaves: Vec<_> = far.iter().flat_map(|&b| mesh.leaves_of_base(b)).collect();
    mesh.refine(&leaves[..3], &|_| false);
    shade(&mesh, &mut cache);
    file.samples_changed(0..mesh.vertex_count() as u32);
    (mesh, cache, file)
}

/// Asks `drop_written` until the writer's commit is in, for 10 s at most.
fn dropped_once_written(
    file: &mut CacheFile,
    mesh: &mut SubdivisionMesh,
    cache: &mut ShadingCache,
    unseen: impl Fn(u32) -> bool,
) -> Option<Dropped> {
    let until = Instant::now() + Duration::from_secs(10);
    while Instant::now() < until {
        if let Some(dropped) = file.drop_written(mesh, cache, &unseen) {
            return Some(dropped);
        }
        std::thread::sleep(crate::cache_file::evict::POLL);
    }
    None
}

#[test]
fn an_unseen_subtree_is_written_dropped_and_comes_back_from_the_file_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    let (mut mesh, mut cache, mut file) = refined_site(&config);
    let far = bases_in(&mesh, 4.5, 6.0);
    let before = shown(&mesh, &cache);
    let (leaves, bytes) = (mesh.leaf_count(), cache.bytes());
    let commits = file.writer_stats().commits;

    // One far base triangle is seen again before the commit is in: it stays.
    let seen_again = far[0];
    let seen_leaves_before = mesh.leaves_of_base(seen_again).len();
    let far_leaves_before: usize = far[1..].iter().map(|&b| mesh.leaves_of_base(b).len()).sum();
    file.write_out(far.clone(), &mut mesh, &cache);
    assert!(file.writing_out());
    let dropped = dropped_once_written(&mut file, &mut mesh, &mut cache, |b| b != seen_again)
        .expect("the commit came in");
    assert!(file.writer_stats().commits > commits, "written first");
    assert_eq!(dropped.bases, far[1..].to_vec());
    assert!(!dropped.steps.is_empty() && dropped.samples > 0);
    // Those beside the base seen again keep what its splits need (the mesh stays conforming).
    let leaves_of = |mesh: &SubdivisionMesh, bases: &[u32]| -> usize {
        bases.iter().map(|&b| mesh.leaves_of_base(b).len()).sum()
    };
    assert!(leaves_of(&mesh, &far[1..]) < far_leaves_before / 2);
    assert_eq!(
        mesh.leaves_of_base(seen_again).len(),
        seen_leaves_before,
        "seen again: kept"
    );
    assert!(mesh.leaf_count() < leaves, "leaves fell");
    assert!(cache.bytes() < bytes, "the cache fell");
    assert!(file.has_unloaded() && !file.is_loaded(far[1]));
    // The near area is untouched.
    let near = |shown: &Shown| {
        shown
            .iter()
            .filter(|(corners, _)| corners.iter().all(|c| f32::from_bits(c[0]) < 1.5))
            .map(|(c, s)| (c.clone(), s.clone()))
            .collect::<Shown>()
    };
    assert_eq!(near(&shown(&mesh, &cache)), near(&before));

    // Seen again, the far area's subtrees and samples come back from the file as they left.
    let steps = file.load(far.iter().copied(), &mut mesh, &mut cache);
    assert!(!steps.is_empty());
    assert_eq!(far_part(&shown(&mesh, &cache)), far_part(&before));
    assert_eq!(mesh.leaf_count(), leaves);

    // And what came back is saved and reopened like any record.
    file.close(&mut mesh, &cache);
    let (mut mesh, mut cache) = fresh();
    open_all(&config, &key(), &mut mesh, &mut cache).unwrap();
    assert_eq!(far_part(&shown(&mesh, &cache)), far_part(&before));
}

#[test]
fn a_subtree_whose_save_fails_stays_in_memory_until_a_commit_succeeds() {
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    let (mut mesh, mut cache, mut file) = refined_site(&config);
    let far = bases_in(&mesh, 4.5, 6.0);
    let before = shown(&mesh, &cache);
    file.writer.fail_commits(true);
    file.write_out(far.clone(), &mut mesh, &cache);
    let until = Instant::now() + Duration::from_secs(10);
    while file.writer_stats().failed_commits == 0 && Instant::now() < until {
        std::thread::sleep(crate::cache_file::evict::POLL);
    }
    assert_eq!(file.writer_stats().failed_commits, 1);
    assert!(
        !file.takes_subtrees(),
        "the schedule coarsens as without a file"
    );
    assert!(file.drop_written(&mut mesh, &mut cache, |_| true).is_none());
    assert_eq!(shown(&mesh, &cache), before, "nothing left memory");
    assert!(far.iter().all(|&b| file.is_loaded(b)));

    // The disk has room again: the next commit holds the failed one's records too.
    file.writer.fail_commits(false);
    file.save_now(&mut mesh, &cache);
    assert!(file.takes_subtrees());
    let dropped = file
        .drop_written(&mut mesh, &mut cache, |_| true)
        .expect("the commit is in");
    assert_eq!(dropped.bases, far);
    file.load(far.iter().copied(), &mut mesh, &mut cache);
    assert_eq!(far_part(&shown(&mesh, &cache)), far_part(&before));
}
