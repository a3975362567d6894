//! The viewer's keys: one list that the key handler, the help overlay and
//! the README's key table all come from, so they cannot disagree (a test
//! holds the README to [`markdown_table`]).

use eframe::egui::Key;

/// What a key pressed once does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    Faster,
    Slower,
    FinerMesh,
    CoarserMesh,
    MeshOrRaycast,
    Wireframe,
    Texture,
    Geomorphing,
    TerrainFollowing,
    Objects,
    Sprites,
    ImpostorAlpha,
    ImpostorBlur,
    CopyCamera,
    Home,
    Help,
}

/// A flight control held down, with the key that drives it up and the one
/// that drives it down.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    Forward,
    Turn,
    Climb,
}

/// How a line of the list is used.
#[derive(Debug, Clone, Copy)]
pub enum Input {
    /// Held keys: `(plus, minus)` of an axis.
    Held(Axis, Key, Key),
    /// Keys pressed once, each with its action.
    Pressed(&'static [(Key, Action)]),
    /// The pointer (drag, scroll): handled by the view, listed for help.
    Pointer,
}

/// One line of the key list.
#[derive(Debug, Clone, Copy)]
pub struct Binding {
    /// The keys as shown to a person.
    pub label: &'static str,
    pub what: &'static str,
    pub input: Input,
}

/// The keys, in the order the help lists them. No two share a key (the
/// seed's `w` wireframe, `t` texture and F1 objects are kept, so flying
/// uses the arrows, not WASD).
pub const BINDINGS: &[Binding] = &[
    Binding {
        label: "↑ ↓",
        what: "fly forward / back",
        input: Input::Held(Axis::Forward, Key::ArrowUp, Key::ArrowDown),
    },
    Binding {
        label: "← →",
        what: "turn left / right",
        input: Input::Held(Axis::Turn, Key::ArrowRight, Key::ArrowLeft),
    },
    Binding {
        label: "PgUp PgDn",
        what: "climb / sink along the terrain normal",
        input: Input::Held(Axis::Climb, Key::PageUp, Key::PageDown),
    },
    Binding {
        label: "drag",
        what: "turn and look up / down",
        input: Input::Pointer,
    },
    Binding {
        label: "right-drag",
        what: "orbit about the ground point under the pointer",
        input: Input::Pointer,
    },
    Binding {
        label: "scroll",
        what: "zoom towards the ground point under the pointer",
        input: Input::Pointer,
    },
    Binding {
        label: "+ −",
        what: "faster / slower",
        input: Input::Pressed(&[
            (Key::Plus, Action::Faster),
            (Key::Equals, Action::Faster),
            (Key::Minus, Action::Slower),
        ]),
    },
    Binding {
        label: "[ ]",
        what: "finer / coarser mesh (τ)",
        input: Input::Pressed(&[
            (Key::OpenBracket, Action::FinerMesh),
            (Key::CloseBracket, Action::CoarserMesh),
        ]),
    },
    Binding {
        label: "m",
        what: "mesh / raycast",
        input: Input::Pressed(&[(Key::M, Action::MeshOrRaycast)]),
    },
    Binding {
        label: "w",
        what: "wireframe",
        input: Input::Pressed(&[(Key::W, Action::Wireframe)]),
    },
    Binding {
        label: "t",
        what: "drape texture",
        input: Input::Pressed(&[(Key::T, Action::Texture)]),
    },
    Binding {
        label: "g",
        what: "geomorphing",
        input: Input::Pressed(&[(Key::G, Action::Geomorphing)]),
    },
    Binding {
        label: "f",
        what: "terrain following",
        input: Input::Pressed(&[(Key::F, Action::TerrainFollowing)]),
    },
    Binding {
        label: "F1",
        what: "objects and vegetation",
        input: Input::Pressed(&[(Key::F1, Action::Objects)]),
    },
    Binding {
        label: "F12",
        what: "vegetation as sprites / billboards",
        input: Input::Pressed(&[(Key::F12, Action::Sprites)]),
    },
    Binding {
        label: "c",
        what: "impostors' alpha (off: whole quads)",
        input: Input::Pressed(&[(Key::C, Action::ImpostorAlpha)]),
    },
    Binding {
        label: "b",
        what: "impostors' filtering (blur)",
        input: Input::Pressed(&[(Key::B, Action::ImpostorBlur)]),
    },
    Binding {
        label: "p",
        what: "copy the camera pose string",
        input: Input::Pressed(&[(Key::P, Action::CopyCamera)]),
    },
    Binding {
        label: "Home",
        what: "home view",
        input: Input::Pressed(&[(Key::Home, Action::Home)]),
    },
    Binding {
        label: "h",
        what: "this help",
        input: Input::Pressed(&[(Key::H, Action::Help)]),
    },
];

/// The key of an action, as a person reads it in a label ("geomorphing (g)").
pub fn label_of(action: Action) -> &'static str {
    BINDINGS
        .iter()
        .find(|b| matches!(b.input, Input::Pressed(keys) if keys.iter().any(|&(_, a)| a == action)))
        .map_or("", |b| b.label)
}

/// The list as the Markdown table the README shows.
pub fn markdown_table() -> String {
    let mut table = String::from("| key | what it does |\n|---|---|\n");
    for b in BINDINGS {
        table.push_str(&format!("| {} | {} |\n", b.label, b.what));
    }
    table
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_two_lines_share_a_key() {
        let mut seen = Vec::new();
        for b in BINDINGS {
            let keys: Vec<Key> = match b.input {
                Input::Held(_, plus, minus) => vec![plus, minus],
                Input::Pressed(keys) => keys.iter().map(|&(k, _)| k).collect(),
                Input::Pointer => Vec::new(),
            };
            for k in keys {
                assert!(!seen.contains(&k), "{k:?} is bound twice");
                seen.push(k);
            }
        }
    }

    #[test]
    fn the_readme_shows_this_list() {
        let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md"))
            .expect("README.md beside the viewer");
        let (start, end) = ("<!-- keys: viewer/src/keys.rs -->\n", "<!-- /keys -->");
        let from = readme.find(start).expect("README marks its key table") + start.len();
        let to = from + readme[from..].find(end).expect("README ends its key table");
        assert_eq!(
            &readme[from..to],
            markdown_table(),
            "README.md's key table differs from viewer/src/keys.rs: paste markdown_table()"
        );
    }

    #[test]
    fn labels_name_the_key_of_an_action() {
        assert_eq!(label_of(Action::CopyCamera), "p");
        assert_eq!(label_of(Action::Geomorphing), "g");
    }
}
