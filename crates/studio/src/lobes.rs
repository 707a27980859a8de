//! Lobe tracing from the page (McPhail §5.6.3): the messages that edit the fissure script of
//! a `lobes` derived object (made by the `lungs` set-up, [`volmorph_scene::setup::Setup::Lungs`]) and
//! the scene command each becomes.
//!
//! * `{"command": "trace-lobes", "id": LOBES, "fissure": F, "slice": K, "from": [i, j],
//!   "to": [i, j]}` — the two points the user clicked on axial section `K` (continuous voxel
//!   indices) become the key of fissure `F` there, in place of a key at that section;
//! * `{"command": "lobe-range", "id": LOBES, "fissure": F, "first": K0, "last": K1}` — the
//!   fissure is traced from section `K0` to `K1`;
//! * `{"command": "remove-lobe-key", "id": LOBES, "fissure": F, "slice": K}` — its key at
//!   section `K` goes.
//!
//! `F` is `right-oblique`, `right-horizontal` or `left-oblique`. Each becomes a
//! [`Command::SetRecipe`] of the object with the edited script (the script editing and its
//! checks are `volmorph_register::lungs::LobeScript`'s), so the lobes are traced again and
//! undo and redo restore the previous script and labels like any scene edit.

use serde_json::Value;
use volmorph_register::lungs::{FissureKind, KeyPoints};
use volmorph_scene::{Command, Object, ObjectId, Recipe, Scene, SceneError};
use volmorph_volume::AnyVolume;

use crate::views::{QueryError, u64_field};

/// What a lobe-tracing message changes in a fissure of the script.
#[derive(Debug, Clone, PartialEq)]
pub enum LobeEdit {
    /// Add this key, in place of the fissure's key at its section if there is one.
    Key(KeyPoints),
    /// Trace the fissure from section `first` to section `last` (inclusive).
    Range {
        /// First section.
        first: usize,
        /// Last section.
        last: usize,
    },
    /// Remove the fissure's key at section `slice`.
    RemoveKey {
        /// The key's section.
        slice: usize,
    },
}

/// A lobe-tracing message (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct LobeRequest {
    /// The `lobes` derived object.
    pub id: ObjectId,
    /// The fissure edited.
    pub fissure: FissureKind,
    /// The edit.
    pub edit: LobeEdit,
}

fn usize_field(h: &Value, name: &str) -> Result<usize, QueryError> {
    usize::try_from(u64_field(h, name)?).map_err(|e| QueryError(format!("field {name:?}: {e}")))
}

/// The pixel `[i, j]` of field `name`: two finite numbers.
fn pixel_field(h: &Value, name: &str) -> Result<[f64; 2], QueryError> {
    let bad = || {
        QueryError(format!(
            "field {name:?} must be a pixel [i, j] of two finite numbers"
        ))
    };
    match h.get(name).and_then(Value::as_array).map(Vec::as_slice) {
        Some([i, j]) => {
            let p = [i.as_f64().ok_or_else(bad)?, j.as_f64().ok_or_else(bad)?];
            if p.iter().all(|v| v.is_finite()) {
                Ok(p)
            } else {
                Err(bad())
            }
        }
        _ => Err(bad()),
    }
}

/// The lobe-tracing request of a `trace-lobes`, `lobe-range` or `remove-lobe-key` message, or
/// `None` for any other command.
///
/// # Errors
/// A missing or malformed field, naming it; an unknown fissure, naming the known ones.
pub fn parse(h: &Value) -> Result<Option<LobeRequest>, QueryError> {
    let command = h.get("command").and_then(Value::as_str);
    if !matches!(
        command,
        Some("trace-lobes" | "lobe-range" | "remove-lobe-key")
    ) {
        return Ok(None);
    }
    let fissure: FissureKind = h
        .get("fissure")
        .and_then(Value::as_str)
        .ok_or_else(|| QueryError("field \"fissure\" must be a string".into()))?
        .parse()
        .map_err(|e: volmorph_register::RegisterError| QueryError(e.to_string()))?;
    let edit = match command {
        Some("trace-lobes") => LobeEdit::Key(KeyPoints {
            slice: usize_field(h, "slice")?,
            from: pixel_field(h, "from")?,
            to: pixel_field(h, "to")?,
        }),
        Some("lobe-range") => LobeEdit::Range {
            first: usize_field(h, "first")?,
            last: usize_field(h, "last")?,
        },
        _ => LobeEdit::RemoveKey {
            slice: usize_field(h, "slice")?,
        },
    };
    Ok(Some(LobeRequest {
        id: ObjectId(u64_field(h, "id")?),
        fissure,
        edit,
    }))
}

/// The scene command of a lobe-tracing request: the recipe of the `lobes` object `r.id` with
/// its script edited. A new key is checked against the lung mask first (its section in the
/// volume and holding the fissure's lung, its points on the section); the scene checks the
/// whole script against the grid when it applies the command.
///
/// # Errors
/// [`SceneError::NoObject`] / [`SceneError::WrongKind`] if `r.id` is not a derived object,
/// [`SceneError::Invalid`] if it is not a `lobes` one, [`SceneError::Register`] for a key
/// that does not fit, a key to remove that is missing or a range that cuts a key off.
pub fn command(scene: &Scene, r: LobeRequest) -> Result<Command, SceneError> {
    let entry = scene.get(r.id)?;
    let Object::Derived(d) = &entry.object else {
        return Err(SceneError::WrongKind {
            id: r.id,
            name: entry.name.clone(),
            expected: "lobes object",
            found: entry.object.kind(),
        });
    };
    let Recipe::Lobes {
        lungs,
        boundaries,
        script,
    } = d.recipe()
    else {
        return Err(SceneError::Invalid(format!(
            "object {} ({:?}) is a {} object, not the lobes of a lung set-up",
            r.id,
            entry.name,
            d.recipe().name()
        )));
    };
    let mut script = script.clone();
    match r.edit {
        LobeEdit::Key(key) => {
            let mask = scene.volume(*lungs)?;
            match &**mask {
                AnyVolume::U8(m) => key.check_on(r.fissure, m)?,
                other => key.check_on(r.fissure, &other.to_typed())?,
            }
            script.set_key(r.fissure, key);
        }
        LobeEdit::Range { first, last } => script.set_range(r.fissure, first, last)?,
        LobeEdit::RemoveKey { slice } => {
            script.remove_key(r.fissure, slice)?;
        }
    }
    Ok(Command::SetRecipe {
        id: r.id,
        recipe: Recipe::Lobes {
            lungs: *lungs,
            boundaries: *boundaries,
            script,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;
    use serde_json::json;
    use volmorph_register::lungs::{LEFT_LUNG, LobeScript, RIGHT_LUNG, dice};
    use volmorph_register::phantom::{LungPhantom, LungPhantomOptions, lobe, lung_phantom};
    use volmorph_scene::{Change, NewObject};

    use volmorph_scene::setup::Setup;

    /// A lung phantom's inhale scan in a scene and the lung set-up run on it: the phantom, the
    /// scene and the ids of the scan and of the set-up's lungs, boundaries and lobes.
    fn lung_scene(dims: [usize; 3], spacing: DVec3) -> (LungPhantom, Scene, [ObjectId; 4]) {
        let ph = lung_phantom(&LungPhantomOptions {
            dims,
            spacing,
            ..LungPhantomOptions::default()
        })
        .unwrap();
        let mut scene = Scene::new();
        let ct = scene
            .apply(Command::Add {
                name: "inhale".into(),
                object: NewObject::Volume(AnyVolume::from(ph.inhale.clone())),
            })
            .unwrap()
            .added[0];
        let depth = scene.undo_depth();
        let c = Setup::Lungs {
            ct: ct.0,
            options: Default::default(),
        }
        .run(&mut scene)
        .unwrap();
        assert_eq!(scene.undo_depth(), depth + 1, "the set-up is one undo step");
        let [lungs, boundaries, lobes] = c.added[..] else {
            panic!("the set-up adds three objects: {:?}", c.added);
        };
        for (id, name) in [
            (lungs, "inhale lungs"),
            (boundaries, "inhale lobe boundaries"),
            (lobes, "inhale lobes"),
        ] {
            assert_eq!(scene.get(id).unwrap().name, name);
        }
        (ph, scene, [ct, lungs, boundaries, lobes])
    }

    /// A message as a page sends it, applied.
    fn send(scene: &mut Scene, h: &Value) -> Result<Change, SceneError> {
        let r = parse(h)
            .map_err(|e| SceneError::Invalid(e.0))?
            .expect("a lobe-tracing message");
        let c = command(scene, r)?;
        scene.apply(c)
    }

    fn labels(scene: &Scene, id: ObjectId) -> Vec<u8> {
        scene.volume(id).unwrap().to_typed::<u8>().data().to_vec()
    }

    fn script(scene: &Scene, id: ObjectId) -> LobeScript {
        let Object::Derived(d) = &scene.get(id).unwrap().object else {
            panic!("lobes are a derived object");
        };
        let Recipe::Lobes { script, .. } = d.recipe() else {
            panic!("a lobes recipe");
        };
        script.clone()
    }

    fn key_message(lobes: ObjectId, kind: FissureKind, k: &KeyPoints) -> Value {
        json!({"command": "trace-lobes", "id": lobes.0, "fissure": kind.name(),
            "slice": k.slice, "from": k.from, "to": k.to})
    }

    /// The lung phantom set up from the studio: the lung mask agrees with the true lungs;
    /// the phantom's fissure key points sent as clicked keys (and each fissure's range) make
    /// the phantom's script, and the lobes reach a Dice coefficient of at least 0.9 against
    /// the true lobes; each message is one undo step, and undo and redo restore the labels
    /// and the script exactly.
    #[test]
    fn clicked_keys_label_the_phantom_lobes_and_undo_restores_them() {
        let (ph, mut scene, [_, lungs, _, lobes]) =
            lung_scene([88, 72, 64], DVec3::new(3.0, 3.0, 3.5));
        let side = |l: u8| match l {
            lobe::RUL | lobe::RML | lobe::RLL => RIGHT_LUNG,
            lobe::LUL | lobe::LLL => LEFT_LUNG,
            _ => 0,
        };
        let truth: Vec<u8> = ph.lobes.data().iter().map(|&l| side(l)).collect();
        for l in [RIGHT_LUNG, LEFT_LUNG] {
            let d = dice(&labels(&scene, lungs), &truth, l);
            assert!(d > 0.95, "lung {l}: Dice {d}");
        }
        let mut ms = Vec::new();
        let mut before_left = (Vec::new(), 0);
        for f in &ph.lobe_script.fissures {
            if f.kind == FissureKind::LeftOblique {
                before_left = (labels(&scene, lobes), scene.undo_depth());
            }
            for k in &f.keys {
                let depth = scene.undo_depth();
                let t = std::time::Instant::now();
                let c = send(&mut scene, &key_message(lobes, f.kind, k)).unwrap();
                ms.push(t.elapsed().as_secs_f64() * 1e3);
                assert!(c.modified.contains(&lobes) && c.errors.is_empty(), "{c:?}");
                assert_eq!(scene.undo_depth(), depth + 1);
            }
            send(
                &mut scene,
                &json!({"command": "lobe-range", "id": lobes.0, "fissure": f.kind.name(),
                    "first": f.first, "last": f.last}),
            )
            .unwrap();
        }
        ms.sort_by(f64::total_cmp);
        eprintln!(
            "trace-lobes on {:?} voxels: median {:.1} ms, max {:.1} ms over {} keys",
            ph.inhale.geometry().dims,
            ms[ms.len() / 2],
            ms[ms.len() - 1],
            ms.len()
        );
        assert_eq!(script(&scene, lobes), ph.lobe_script);
        let full = labels(&scene, lobes);
        for l in 1..=5u8 {
            let d = dice(&full, ph.lobes.data(), l);
            eprintln!("{}: Dice {d:.3}", lobe::NAMES[l as usize]);
            assert!(d >= 0.9, "{}: Dice {d}", lobe::NAMES[l as usize]);
        }
        // Undo the left fissure's keys and range: the labels are as before them.
        let steps = scene.undo_depth() - before_left.1;
        for _ in 0..steps {
            scene.undo().unwrap();
        }
        assert_eq!(labels(&scene, lobes), before_left.0);
        assert!(
            script(&scene, lobes)
                .fissure(FissureKind::LeftOblique)
                .is_none()
        );
        for _ in 0..steps {
            scene.redo().unwrap();
        }
        assert_eq!(labels(&scene, lobes), full);
        // A key removed and the removal undone.
        let k = &ph.lobe_script.fissures[0].keys[1];
        send(
            &mut scene,
            &json!({"command": "remove-lobe-key", "id": lobes.0,
                "fissure": ph.lobe_script.fissures[0].kind.name(), "slice": k.slice}),
        )
        .unwrap();
        assert_ne!(script(&scene, lobes), ph.lobe_script);
        scene.undo().unwrap();
        assert_eq!(script(&scene, lobes), ph.lobe_script);
        assert_eq!(labels(&scene, lobes), full);
    }

    /// Malformed messages and keys, ranges or objects that do not fit are refused with a
    /// message naming the problem, and change nothing.
    #[test]
    fn bad_lobe_messages_are_refused_and_change_nothing() {
        let (_, mut scene, [ct, lungs, _, lobes]) =
            lung_scene([48, 40, 36], DVec3::new(6.0, 6.0, 7.0));
        let mask = scene.volume(lungs).unwrap().to_typed::<u8>();
        let [nx, ny, nz] = mask.geometry().dims;
        let holds = |k: usize, l: u8| mask.data()[k * nx * ny..(k + 1) * nx * ny].contains(&l);
        let with_right = (0..nz).find(|&k| holds(k, RIGHT_LUNG)).unwrap();
        let without_right = (0..nz).find(|&k| !holds(k, RIGHT_LUNG)).unwrap();
        let key = |slice: usize, from: [f64; 2]| {
            json!({"command": "trace-lobes", "id": lobes.0, "fissure": "right-oblique",
                "slice": slice, "from": from, "to": [nx as f64 / 2.0, ny as f64 / 2.0]})
        };
        send(&mut scene, &key(with_right, [2.0, 2.0])).unwrap();
        let depth = scene.undo_depth();
        let before = labels(&scene, lobes);
        let mut bad = |h: Value, named: &str| {
            let e = send(&mut scene, &h).unwrap_err().to_string();
            assert!(e.contains(named), "{named:?} not in {e:?}");
        };
        bad(
            json!({"command": "trace-lobes", "id": lobes.0, "fissure": "middle", "slice": 1,
                "from": [1, 1], "to": [2, 2]}),
            "right-horizontal",
        );
        bad(
            json!({"command": "trace-lobes", "id": lobes.0, "fissure": "left-oblique",
                "slice": 1, "from": [1, 1]}),
            "\"to\"",
        );
        bad(
            json!({"command": "trace-lobes", "id": lobes.0, "fissure": "left-oblique",
                "slice": 1, "from": [1], "to": [2, 2]}),
            "\"from\"",
        );
        bad(
            json!({"command": "trace-lobes", "id": lobes.0, "fissure": "left-oblique",
                "slice": -1, "from": [1, 1], "to": [2, 2]}),
            "\"slice\"",
        );
        bad(key(nz + 5, [2.0, 2.0]), "sections");
        bad(key(with_right, [nx as f64 + 3.0, 2.0]), "outside");
        bad(key(without_right, [2.0, 2.0]), "right lung");
        let mut other = key(with_right, [2.0, 2.0]);
        other["id"] = json!(lungs.0);
        bad(other.clone(), "lobes object");
        other["id"] = json!(999);
        bad(other, "999");
        bad(
            json!({"command": "remove-lobe-key", "id": lobes.0, "fissure": "right-oblique",
                "slice": with_right + 1}),
            "no key",
        );
        bad(
            json!({"command": "lobe-range", "id": lobes.0, "fissure": "left-oblique",
                "first": 0, "last": 3}),
            "no key yet",
        );
        bad(
            json!({"command": "lobe-range", "id": lobes.0, "fissure": "right-oblique",
                "first": 0, "last": nz}),
            "reaches section",
        );
        bad(
            json!({"command": "lobe-range", "id": lobes.0, "fissure": "right-oblique",
                "first": with_right + 1, "last": nz - 1}),
            "remove the key",
        );
        assert_eq!(scene.undo_depth(), depth);
        assert_eq!(labels(&scene, lobes), before);
        // Other commands are not lobe messages.
        assert!(
            parse(&json!({"command": "rename", "id": ct.0}))
                .unwrap()
                .is_none()
        );
    }

    /// A cancelled lung set-up changes nothing.
    #[test]
    fn a_cancelled_lung_setup_changes_nothing() {
        let (ph, mut scene, [ct, ..]) = lung_scene([40, 36, 32], DVec3::new(7.0, 7.0, 8.0));
        let (count, depth) = (scene.objects().count(), scene.undo_depth());
        for after in [1, 6, 12] {
            let e = Setup::Lungs {
                ct: ct.0,
                options: Default::default(),
            }
            .run_with(
                &mut scene,
                &volmorph_io::progress::Counter::cancel_after(after),
            )
            .unwrap_err();
            assert!(e.is_cancelled(), "{e}");
            assert_eq!(
                (scene.objects().count(), scene.undo_depth()),
                (count, depth)
            );
        }
        drop(ph);
    }
}
