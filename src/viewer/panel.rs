//! The viewer's interface, laid out with egui: the material (preset, coefficients, index,
//! model, blending), the derived settings and their overrides, the lights (kind, direction on a
//! sphere, colour, intensity; add and remove), the per-pass GPU times of the last frames as a
//! plot, and the screenshot and save-scene buttons.
//!
//! The panel changes nothing itself: every control emits an [`Action`], the same one a script
//! command or a key produces, and the viewer applies it. What the panel shows comes in a
//! [`Snapshot`] taken before the layout.

use super::script::Action;
use crate::physics::material::PRESETS;
use crate::physics::{Material, Model};
use crate::preprocess::operators::Blend;
use crate::preprocess::settings::SettingsOverrides;
use crate::scene::desc::LightKind;
use crate::scene::{Light, MAX_LIGHTS};
use clap::ValueEnum;
use egui::{Color32, Pos2, Rect, Sense, Stroke, Vec2};
use glam::Vec3;

/// What the panel shows, taken from the viewer before each layout.
pub struct Snapshot {
    /// Device name and type.
    pub device: String,
    /// Frames per second over the last frames.
    pub fps: f64,
    /// Median GPU and wall time of a frame over the last frames, ms.
    pub frame_ms: Option<(f64, f64)>,
    /// What the viewer last said (a saved file, an error, a finished preprocessing).
    pub status: String,
    /// A running preprocessing: what for, its stage, the fraction done and the seconds so far.
    pub progress: Option<(String, String, f32, f64)>,
    /// The preset shown or asked for (None: coefficients of one's own).
    pub preset: Option<String>,
    /// The material shown or asked for.
    pub material: Material,
    /// The material the image currently shows, when the one asked for is still being prepared.
    pub shown: Option<String>,
    /// The blending mode.
    pub mode: Blend,
    /// The texel in use, mm.
    pub texel_mm: f64,
    /// The kernel's edge in use, texels.
    pub kernel_size: u32,
    /// The global response's node count.
    pub nodes: usize,
    /// The nodes' spacing in use, mm.
    pub node_spacing_mm: f64,
    /// The pruning tolerance in use (fraction).
    pub prune_tolerance: f64,
    /// The settings given instead of derived.
    pub overrides: SettingsOverrides,
    /// The lights as shown (world space, the view's turn applied).
    pub lights: Vec<Light>,
    /// The camera's right, up and backward axes (the light sphere is drawn in them).
    pub camera_axes: [Vec3; 3],
    /// Per pass: its name and its GPU time in each of the last frames (NaN: skipped).
    pub passes: Vec<(String, Vec<f64>)>,
    /// The GPU time of each of the last frames, ms.
    pub frames: Vec<f64>,
    /// The material shown or asked for as artists give it: its colour and scatter distance
    /// (None where it has none).
    pub appearance: Option<Appearance>,
    /// The display's exposure.
    pub exposure: f64,
    /// The display's tone curve.
    pub tonemap: crate::output::ToneMap,
    /// Whether the environment shows behind the object (None: the scene has none).
    pub backdrop: Option<bool>,
    /// Degrees the camera turns each frame.
    pub turntable: f32,
}

/// What the panel keeps between frames (not part of the scene).
#[derive(Debug, Clone, Default)]
pub struct PanelState {
    /// The override fields as edited, applied with the button.
    pub overrides: Option<SettingsOverrides>,
    /// The settings given when the fields were last filled: given ones that change
    /// elsewhere (a coefficient edit pins those in use) fill them again.
    pub overrides_seen: Option<SettingsOverrides>,
    /// Lights whose direction is on the far side of the sphere (behind the object).
    pub behind: Vec<bool>,
}

/// Colours of the passes in the plot (cycled).
const PASS_COLOURS: [Color32; 8] = [
    Color32::from_rgb(230, 159, 0),
    Color32::from_rgb(86, 180, 233),
    Color32::from_rgb(0, 158, 115),
    Color32::from_rgb(240, 228, 66),
    Color32::from_rgb(0, 114, 178),
    Color32::from_rgb(213, 94, 0),
    Color32::from_rgb(204, 121, 167),
    Color32::from_rgb(170, 170, 170),
];

fn kind_name(k: LightKind) -> &'static str {
    match k {
        LightKind::Directional => "directional",
        LightKind::Point => "point",
        LightKind::Spot => "spot",
        LightKind::Environment => "environment",
    }
}

/// The panel's width, and its margin to the window's edges.
const WIDTH: f32 = 300.0;
const MARGIN: f32 = 8.0;

/// Columns the window keeps left of the image for the panel: the object is framed beside it,
/// not under it.
pub const SPACE: u32 = (WIDTH + 2.0 * MARGIN) as u32;

/// Columns of image the window keeps at the least, beside the panel.
pub const MIN_VIEW: u32 = 64;

/// Lays the panel out and appends what the user did to `actions`.
pub fn show(ctx: &egui::Context, s: &Snapshot, st: &mut PanelState, actions: &mut Vec<Action>) {
    // As tall as the window at most: the rest scrolls.
    let height = ctx.content_rect().height() - 2.0 * MARGIN;
    egui::Window::new("translucent")
        .default_pos([MARGIN, MARGIN])
        .default_width(WIDTH)
        .max_width(WIDTH)
        .default_height(height.max(100.0))
        .max_height(height.max(100.0))
        .resizable(false)
        .show(ctx, |ui| {
            ui.label(format!("{}  {:.1} fps", s.device, s.fps));
            ui.label(match s.frame_ms {
                Some((gpu, wall)) => format!("frame: GPU {gpu:.2} ms, wall {wall:.2} ms (medians)"),
                None => "frame: timing...".into(),
            });
            // The controls keep their places: nothing above them comes and goes (the input
            // test clicks and drags them where they lie in the default window).
            ui.horizontal(|ui| {
                if ui.button("Screenshot").clicked() {
                    actions.push(Action::Screenshot(None));
                }
                if ui.button("Save scene").clicked() {
                    actions.push(Action::SaveScene(None));
                }
            });
            // Taller than a small window: the rest scrolls.
            egui::ScrollArea::vertical()
                .max_height(ui.available_height())
                .auto_shrink([false, true])
                .show(ui, |ui| {
                    egui::CollapsingHeader::new("Material")
                        .default_open(true)
                        .show(ui, |ui| material(ui, s, actions));
                    egui::CollapsingHeader::new("Settings")
                        .default_open(false)
                        .show(ui, |ui| settings(ui, s, st, actions));
                    egui::CollapsingHeader::new("Lights")
                        .default_open(true)
                        .show(ui, |ui| lights(ui, s, st, actions));
                    // After the sections above, whose controls keep their places.
                    egui::CollapsingHeader::new("Material as colour and scatter distance")
                        .default_open(false)
                        .show(ui, |ui| appearance(ui, s, actions));
                    egui::CollapsingHeader::new("Look")
                        .default_open(false)
                        .show(ui, |ui| look(ui, s, actions));
                    egui::CollapsingHeader::new("GPU time per pass")
                        .default_open(true)
                        .show(ui, |ui| plot(ui, s));
                    // What comes and goes stays last: the controls above keep their places.
                    if let Some((what, stage, done, seconds)) = &s.progress {
                        ui.add(
                            egui::ProgressBar::new(*done)
                                .text(format!("preparing {what}: {stage} ({seconds:.1} s)")),
                        );
                    }
                    if let Some(shown) = &s.shown {
                        ui.label(format!("shown meanwhile: {shown}"));
                    }
                    if !s.status.is_empty() {
                        ui.label(&s.status);
                    }
                });
        });
}

/// The material as artists give it: the colour it shows (the half-space's total diffuse
/// reflectance, linear) and the scatter distance (1 / sigma_t', mm) per channel; an edit
/// finds the coefficients (`Material::from_appearance`) at the index in use.
fn appearance(ui: &mut egui::Ui, s: &Snapshot, actions: &mut Vec<Action>) {
    let Some((albedo, distance)) = s.appearance else {
        ui.label("(no appearance for this material)");
        return;
    };
    egui::Grid::new("appearance").show(ui, |ui| {
        channel_header(ui, "");
        // Values outside a field's range are shown as they are: clamped where edited only, not
        // pushed back each frame as an edit.
        let colour = Field {
            range: 1e-4..=0.999,
            speed: |_| 0.002,
            decimals: 4,
            clamp_existing: false,
        };
        if let Some(v) = channel_row(ui, "colour", albedo, &colour) {
            actions.push(Action::Albedo(v));
        }
        let scatter = Field {
            range: 1e-3..=1e3,
            speed: |x| 0.005 * x.max(1e-3),
            decimals: 4,
            clamp_existing: false,
        };
        if let Some(v) = channel_row(ui, "scatter mm", distance, &scatter) {
            actions.push(Action::ScatterDistance(v));
        }
    });
}

/// A material's colour shown and scatter distance (mm) per channel.
pub type Appearance = ([f64; 3], [f64; 3]);

/// How a row of per-channel drag fields takes its values.
struct Field {
    range: std::ops::RangeInclusive<f64>,
    /// The drag's step at a value.
    speed: fn(f64) -> f64,
    decimals: usize,
    /// Whether a value outside the range is pulled into it even where not edited.
    clamp_existing: bool,
}

/// The header of a grid of per-channel rows: `corner`, then the channels' names.
fn channel_header(ui: &mut egui::Ui, corner: &str) {
    ui.label(corner);
    for c in ["red", "green", "blue"] {
        ui.label(c);
    }
    ui.end_row();
}

/// A grid row: `label` and a drag field per channel; the values as edited, if any was.
fn channel_row(ui: &mut egui::Ui, label: &str, values: [f64; 3], f: &Field) -> Option<[f64; 3]> {
    ui.label(label);
    let mut v = values;
    let mut changed = false;
    for x in v.iter_mut() {
        let speed = (f.speed)(*x);
        changed |= ui
            .add(
                egui::DragValue::new(x)
                    .range(f.range.clone())
                    .clamp_existing_to_range(f.clamp_existing)
                    .speed(speed)
                    .max_decimals(f.decimals),
            )
            .changed();
    }
    ui.end_row();
    changed.then_some(v)
}

/// The display: exposure (in stops about the scene's), the environment as a backdrop, and the
/// tone curve.
fn look(ui: &mut egui::Ui, s: &Snapshot, actions: &mut Vec<Action>) {
    let mut stops = s.exposure.log2();
    if ui
        .add(
            egui::Slider::new(&mut stops, -10.0..=10.0)
                .text("exposure (stops)")
                .clamping(egui::SliderClamping::Edits),
        )
        .changed()
        && (2f64.powf(stops) / s.exposure - 1.0).abs() > 1e-9
    {
        actions.push(Action::Exposure(2f64.powf(stops)));
    }
    if let Some(on) = s.backdrop {
        let mut shown = on;
        if ui
            .checkbox(&mut shown, "the environment behind the object")
            .changed()
        {
            actions.push(Action::Backdrop(shown));
        }
    }
    let mut turn = s.turntable;
    if ui
        .add(
            egui::Slider::new(&mut turn, 0.0..=5.0)
                .text("turntable (degrees a frame)")
                .clamping(egui::SliderClamping::Edits),
        )
        .changed()
        && turn != s.turntable
    {
        actions.push(Action::Turntable(turn));
    }
    egui::ComboBox::from_label("tone curve")
        .selected_text(s.tonemap.name())
        .show_ui(ui, |ui| {
            for curve in crate::output::ToneMap::ALL {
                if ui
                    .selectable_label(curve == s.tonemap, curve.name())
                    .clicked()
                    && curve != s.tonemap
                {
                    actions.push(Action::ToneMap(curve));
                }
            }
        });
}

fn material(ui: &mut egui::Ui, s: &Snapshot, actions: &mut Vec<Action>) {
    let current = s.preset.clone().unwrap_or_else(|| "custom".into());
    egui::ComboBox::from_label("preset")
        .selected_text(&current)
        .show_ui(ui, |ui| {
            for (name, ..) in PRESETS {
                if ui.selectable_label(current == *name, *name).clicked() && current != *name {
                    actions.push(Action::Material(name.to_string()));
                }
            }
        });
    let m = &s.material;
    egui::Grid::new("coefficients").show(ui, |ui| {
        channel_header(ui, "1/mm");
        let coefficient = Field {
            range: 1e-5..=100.0,
            speed: |x| 0.005 * x.max(1e-4),
            decimals: 5,
            clamp_existing: true,
        };
        for (label, values, make) in [
            (
                "sigma_s'",
                m.sigma_s_prime,
                Action::SigmaS as fn([f64; 3]) -> Action,
            ),
            ("sigma_a", m.sigma_a, Action::SigmaA),
        ] {
            if let Some(v) = channel_row(ui, label, values, &coefficient) {
                actions.push(make(v));
            }
        }
    });
    let mut eta = m.eta;
    if ui
        .add(
            egui::Slider::new(&mut eta, 1.0..=2.0)
                .text("eta")
                .step_by(0.01),
        )
        .changed()
    {
        actions.push(Action::Eta(eta));
    }
    egui::ComboBox::from_label("model")
        .selected_text(m.model.name())
        .show_ui(ui, |ui| {
            for &model in Model::value_variants() {
                let allowed = model.refracts() || m.eta == 1.0;
                let item = ui.add_enabled(
                    allowed,
                    egui::Button::selectable(m.model == model, model.name()),
                );
                if item.clicked() && m.model != model {
                    actions.push(Action::Model(model));
                }
            }
        });
    ui.horizontal(|ui| {
        ui.label("blending");
        for mode in Blend::ALL {
            if ui.selectable_label(s.mode == mode, mode.name()).clicked() && s.mode != mode {
                actions.push(Action::Mode(mode));
            }
        }
    });
}

fn settings(ui: &mut egui::Ui, s: &Snapshot, st: &mut PanelState, actions: &mut Vec<Action>) {
    ui.label(format!(
        "in use: texel {:.3} mm, kernel {k}x{k}, {} nodes {:.2} mm apart, pruning {:.2} %",
        s.texel_mm,
        s.nodes,
        s.node_spacing_mm,
        100.0 * s.prune_tolerance,
        k = s.kernel_size
    ));
    if st.overrides_seen != Some(s.overrides) {
        st.overrides_seen = Some(s.overrides);
        st.overrides = Some(s.overrides);
    }
    let edit = st.overrides.get_or_insert(s.overrides);
    let row = |ui: &mut egui::Ui, label: &str, value: &mut Option<f64>, derived: f64| {
        ui.horizontal(|ui| {
            let mut given = value.is_some();
            ui.checkbox(&mut given, label);
            match (given, value.as_mut()) {
                (true, Some(v)) => {
                    let speed = 0.01 * *v;
                    ui.add(egui::DragValue::new(v).speed(speed).range(1e-4..=1e4));
                }
                (true, None) => *value = Some(derived),
                (false, _) => {
                    *value = None;
                    ui.label(format!("derived ({derived:.4})"));
                }
            }
        });
    };
    row(ui, "texel, mm", &mut edit.texel_mm, s.texel_mm);
    row(
        ui,
        "node spacing, mm",
        &mut edit.node_spacing_mm,
        s.node_spacing_mm,
    );
    row(
        ui,
        "pruning tolerance",
        &mut edit.prune_tolerance,
        s.prune_tolerance,
    );
    let mut kernel = edit.kernel_size.map(f64::from);
    row(ui, "kernel, texels", &mut kernel, s.kernel_size as f64);
    edit.kernel_size = kernel.map(|k| (k.round() as u32) | 1);
    ui.horizontal(|ui| {
        let changed = *edit != s.overrides;
        if ui
            .add_enabled(changed, egui::Button::new("Apply (rebuilds)"))
            .clicked()
        {
            actions.push(Action::Settings(*edit));
        }
        if ui.button("All derived").clicked() {
            *edit = SettingsOverrides::default();
            actions.push(Action::Settings(*edit));
        }
    });
    ui.small(
        "An edit of the coefficients, index or model keeps these (given), so that the \
         operators are re-weighted on the same atlas; All derived derives them for the \
         material (a new preprocessing).",
    );
}

fn lights(ui: &mut egui::Ui, s: &Snapshot, st: &mut PanelState, actions: &mut Vec<Action>) {
    st.behind.resize(s.lights.len(), false);
    for (i, l) in s.lights.iter().enumerate() {
        ui.separator();
        ui.push_id(i, |ui| {
            if l.kind == LightKind::Environment {
                ui.label(format!(
                    "light {i}: environment (turn with shift + right drag, [ ])"
                ));
                return;
            }
            ui.horizontal(|ui| {
                ui.label(format!("light {i}"));
                egui::ComboBox::from_id_salt("kind")
                    .selected_text(kind_name(l.kind))
                    .show_ui(ui, |ui| {
                        for k in [LightKind::Directional, LightKind::Point, LightKind::Spot] {
                            if ui.selectable_label(l.kind == k, kind_name(k)).clicked()
                                && l.kind != k
                            {
                                actions.push(Action::LightKind(i, k));
                            }
                        }
                    });
                if s.lights.len() > 1 && ui.button("remove").clicked() {
                    actions.push(Action::RemoveLight(i));
                }
            });
            ui.horizontal(|ui| {
                if let Some(d) = sphere(ui, s, l, &mut st.behind[i]) {
                    actions.push(Action::LightDirection(i, d.to_array()));
                }
                ui.vertical(|ui| {
                    let intensity = l.radiance.max_element();
                    let colour = if intensity > 0.0 {
                        l.radiance / intensity
                    } else {
                        Vec3::ONE
                    };
                    let mut rgb = colour.to_array();
                    if ui.color_edit_button_rgb(&mut rgb).changed() {
                        actions.push(Action::LightColour(i, rgb));
                    }
                    let mut v = intensity;
                    let speed = 0.01 * v.max(0.01);
                    if ui
                        .add(
                            egui::DragValue::new(&mut v)
                                .speed(speed)
                                .range(0.0..=1e6)
                                .prefix("intensity "),
                        )
                        .changed()
                    {
                        actions.push(Action::LightIntensity(i, v));
                    }
                    ui.checkbox(&mut st.behind[i], "from behind");
                });
            });
        });
    }
    if s.lights.len() < MAX_LIGHTS {
        ui.horizontal(|ui| {
            ui.label("add");
            for k in [LightKind::Directional, LightKind::Point, LightKind::Spot] {
                if ui.button(kind_name(k)).clicked() {
                    actions.push(Action::AddLight(k));
                }
            }
        });
    }
}

/// The light's direction as a point on a sphere seen along the camera: where the light comes
/// from (dot filled in front of the object, hollow behind it). Dragging on the disc puts the
/// light there, on the near side or, with `behind`, the far side. Returns the new direction of
/// travel.
fn sphere(ui: &mut egui::Ui, s: &Snapshot, l: &Light, behind: &mut bool) -> Option<Vec3> {
    let size = 84.0;
    let (response, painter) = ui.allocate_painter(Vec2::splat(size), Sense::click_and_drag());
    let rect = response.rect;
    let (c, r) = (rect.center(), 0.45 * size);
    let [right, up, back] = s.camera_axes;
    painter.circle(
        c,
        r,
        Color32::from_gray(40),
        Stroke::new(1.0, Color32::GRAY),
    );
    // Where the camera looks from (the centre), and the sides as the image shows them.
    let label = egui::FontId::proportional(9.0);
    for (text, at, align) in [
        (
            "up",
            Pos2::new(c.x, c.y - r + 2.0),
            egui::Align2::CENTER_TOP,
        ),
        (
            "down",
            Pos2::new(c.x, c.y + r - 2.0),
            egui::Align2::CENTER_BOTTOM,
        ),
        (
            "left",
            Pos2::new(c.x - r + 3.0, c.y),
            egui::Align2::LEFT_CENTER,
        ),
        (
            "right",
            Pos2::new(c.x + r - 3.0, c.y),
            egui::Align2::RIGHT_CENTER,
        ),
    ] {
        painter.text(at, align, text, label.clone(), Color32::from_gray(140));
    }
    painter.line_segment(
        [c - Vec2::new(3.0, 0.0), c + Vec2::new(3.0, 0.0)],
        Stroke::new(1.0, Color32::from_gray(140)),
    );
    painter.line_segment(
        [c - Vec2::new(0.0, 3.0), c + Vec2::new(0.0, 3.0)],
        Stroke::new(1.0, Color32::from_gray(140)),
    );
    let response = response.on_hover_text(
        "where the light comes from, seen from the camera (the cross): filled in front of the \
         object, hollow behind it; drag to move it",
    );
    let from = -l.direction.normalize_or(Vec3::NEG_Z);
    let (x, y, z) = (from.dot(right), from.dot(up), from.dot(back));
    let dot = Pos2::new(c.x + r * x, c.y - r * y);
    if z >= 0.0 {
        painter.circle_filled(dot, 5.0, Color32::YELLOW);
    } else {
        painter.circle_stroke(dot, 5.0, Stroke::new(1.5, Color32::YELLOW));
    }
    let pos = response.interact_pointer_pos()?;
    if !(response.dragged() || response.clicked()) {
        return None;
    }
    let mut p = Vec2::new((pos.x - c.x) / r, (c.y - pos.y) / r);
    if p.length() > 1.0 {
        p /= p.length();
    }
    let z = (1.0 - p.length_sq()).max(0.0).sqrt() * if *behind { -1.0 } else { 1.0 };
    let from = (p.x * right + p.y * up + z * back).normalize_or(Vec3::Y);
    Some(-from)
}

/// The GPU time of every pass over the last frames, one line each, with the frame's total.
fn plot(ui: &mut egui::Ui, s: &Snapshot) {
    let n = s.frames.len();
    if n < 2 {
        ui.label("timing...");
        return;
    }
    let top = s
        .frames
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(0.0f64, f64::max)
        .max(1e-3)
        * 1.1;
    let (response, painter) = ui.allocate_painter(Vec2::new(280.0, 80.0), Sense::hover());
    let rect: Rect = response.rect;
    painter.rect_filled(rect, 2.0, Color32::from_gray(20));
    let at = |k: usize, ms: f64| {
        Pos2::new(
            rect.left() + rect.width() * k as f32 / (n - 1) as f32,
            rect.bottom() - rect.height() * (ms / top) as f32,
        )
    };
    let line = |values: &[f64], colour: Color32, width: f32| {
        let points: Vec<Pos2> = values
            .iter()
            .enumerate()
            .map(|(k, &ms)| at(k, if ms.is_finite() { ms } else { 0.0 }))
            .collect();
        painter.add(egui::Shape::line(points, Stroke::new(width, colour)));
    };
    line(&s.frames, Color32::WHITE, 1.5);
    for (k, (_, values)) in s.passes.iter().enumerate() {
        line(values, PASS_COLOURS[k % PASS_COLOURS.len()], 1.0);
    }
    painter.text(
        rect.left_top() + Vec2::new(4.0, 2.0),
        egui::Align2::LEFT_TOP,
        format!("{top:.1} ms"),
        egui::FontId::monospace(10.0),
        Color32::GRAY,
    );
    let median = |v: &[f64]| {
        let mut v: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied()
    };
    egui::Grid::new("pass legend").show(ui, |ui| {
        ui.colored_label(Color32::WHITE, "frame");
        ui.label(median(&s.frames).map_or("-".into(), |m| format!("{m:.2} ms")));
        ui.end_row();
        for (k, (name, values)) in s.passes.iter().enumerate() {
            ui.colored_label(PASS_COLOURS[k % PASS_COLOURS.len()], name);
            ui.label(median(values).map_or("skipped".into(), |m| format!("{m:.2} ms")));
            ui.end_row();
        }
    });
}
