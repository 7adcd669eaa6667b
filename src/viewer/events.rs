//! The window's events: the panel's share of them first, then keys, drags and the wheel as
//! viewer actions, redraws and the event loop's pace.

use super::script::Action;
use super::{App, Running};
use crate::preprocess::operators::Blend;
use std::time::Instant;
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalPosition;
use winit::event::{ElementState, KeyEvent, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow};
use winit::keyboard::{Key, NamedKey};
use winit::window::WindowId;

/// Degrees of camera orbit per pixel of drag.
const DRAG_DEG_PER_PX: f32 = 0.3;
/// Degrees the lights turn per arrow-key press.
const KEY_LIGHT_DEG: f32 = 10.0;
/// Zoom factor per wheel line.
const WHEEL_ZOOM: f32 = 0.9;
/// Degrees the camera turns each frame once `t` starts the turntable.
const TURNTABLE_DEG: f32 = 1.0;

impl Running {
    /// The action a key press asks for, if any.
    fn key(&self, event: &KeyEvent) -> Option<Action> {
        if event.state != ElementState::Pressed {
            return None;
        }
        Some(match &event.logical_key {
            Key::Named(NamedKey::Escape) => Action::Quit,
            Key::Named(NamedKey::ArrowLeft) => Action::Light(-KEY_LIGHT_DEG, 0.0),
            Key::Named(NamedKey::ArrowRight) => Action::Light(KEY_LIGHT_DEG, 0.0),
            Key::Named(NamedKey::ArrowUp) => Action::Light(0.0, KEY_LIGHT_DEG),
            Key::Named(NamedKey::ArrowDown) => Action::Light(0.0, -KEY_LIGHT_DEG),
            Key::Named(NamedKey::F12) if !event.repeat => Action::Screenshot(None),
            Key::Character(c) => match c.as_str() {
                "q" => Action::Quit,
                "m" if !event.repeat => Action::NextMaterial(1),
                "M" if !event.repeat => Action::NextMaterial(-1),
                "1" => Action::Mode(Blend::Local),
                "2" => Action::Mode(Blend::Global),
                "3" => Action::Mode(self.both_blend),
                "b" if !event.repeat => Action::CycleBlend,
                "p" if !event.repeat => Action::Screenshot(None),
                "h" if !event.repeat => Action::ToggleUi,
                "t" if !event.repeat => Action::Turntable(if self.turntable == 0.0 {
                    TURNTABLE_DEG
                } else {
                    0.0
                }),
                "s" if !event.repeat => Action::SaveScene(None),
                "r" => Action::Reset,
                "e" if !event.repeat => Action::NextEnvironment(1),
                "E" if !event.repeat => Action::NextEnvironment(-1),
                "[" => Action::Environment(-KEY_LIGHT_DEG),
                "]" => Action::Environment(KEY_LIGHT_DEG),
                "+" | "=" => Action::Zoom(WHEEL_ZOOM),
                "-" => Action::Zoom(1.0 / WHEEL_ZOOM),
                _ => return None,
            },
            _ => return None,
        })
    }

    /// Takes the pointer's move to `to`: the action it asks for where a button drags.
    fn mouse_moved(&mut self, to: PhysicalPosition<f64>) -> Option<Action> {
        let from = std::mem::replace(&mut self.cursor, to);
        let (button, _) = self.drag?;
        let (dx, dy) = ((to.x - from.x) as f32, (to.y - from.y) as f32);
        Some(match button {
            MouseButton::Left if self.shift => Action::Pan(dx, dy),
            MouseButton::Left => Action::Orbit(-dx * DRAG_DEG_PER_PX, -dy * DRAG_DEG_PER_PX),
            MouseButton::Right if self.shift => Action::Environment(dx * DRAG_DEG_PER_PX),
            MouseButton::Right => Action::Light(dx * DRAG_DEG_PER_PX, -dy * DRAG_DEG_PER_PX),
            MouseButton::Middle => Action::Pan(dx, dy),
            _ => return None,
        })
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.running.is_none() && self.config.is_some() {
            if let Err(e) = self.start(el) {
                self.fail(el, e);
            }
        }
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(running) = self.running.as_mut() else {
            return;
        };
        // The panel sees every event first. What it takes does not reach the view: a press or
        // the wheel with the pointer over it (decided from where its areas lie, which does
        // not wait for the next layout to see the pointer's new place), or keys while a field
        // is typed in.
        let _ = running.egui_input.on_window_event(&running.window, &event);
        let over_panel = || {
            let ppp = running.egui.pixels_per_point();
            let at = egui::pos2(running.cursor.x as f32 / ppp, running.cursor.y as f32 / ppp);
            // The background layer (the whole screen, under `run_ui`) is the view's.
            let on_area = running
                .egui
                .layer_id_at(at)
                .is_some_and(|l| l.order != egui::Order::Background);
            running.ui_visible && (on_area || running.egui.egui_is_using_pointer())
        };
        let taken = match event {
            WindowEvent::KeyboardInput { .. } => running.egui.egui_wants_keyboard_input(),
            WindowEvent::MouseInput {
                state: ElementState::Pressed,
                ..
            }
            | WindowEvent::MouseWheel { .. } => over_panel(),
            _ => false,
        };
        if taken {
            return;
        }
        let action = match event {
            WindowEvent::CloseRequested => Some(Action::Quit),
            WindowEvent::Resized(_) => {
                running.size_changed = true;
                None
            }
            // A button let go of while the window had no focus never reports its release:
            // no drag outlives the focus (a lamp moved meanwhile is weighed for then).
            WindowEvent::Focused(false) => {
                running.drag = None;
                None
            }
            WindowEvent::ModifiersChanged(m) => {
                running.shift = m.state().shift_key();
                None
            }
            WindowEvent::KeyboardInput { event, .. } => running.key(&event),
            WindowEvent::MouseInput { state, button, .. } => {
                running.drag = match state {
                    ElementState::Pressed => Some((button, running.cursor)),
                    ElementState::Released => None,
                };
                None
            }
            WindowEvent::CursorMoved { position, .. } => running.mouse_moved(position),
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                (lines != 0.0).then(|| Action::Zoom(WHEEL_ZOOM.powf(lines)))
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.redraw(el) {
                    self.fail(el, e);
                }
                None
            }
            _ => None,
        };
        if let Some(a) = action {
            let Some(running) = self.running.as_mut() else {
                return;
            };
            match running.apply(a, &self.settings) {
                Ok(true) => {}
                Ok(false) => el.exit(),
                Err(e) => {
                    // A bad request from the keyboard is shown, not fatal.
                    tracing::error!("{e:#}");
                    running.status = format!("{e:#}");
                }
            }
        }
    }

    fn about_to_wait(&mut self, el: &ActiveEventLoop) {
        if let Some(r) = &self.running {
            let size = r.window.inner_size();
            if size.width == 0 || size.height == 0 {
                // Minimised: sleep until an event arrives, but keep polling a running job.
                el.set_control_flow(if r.busy() {
                    ControlFlow::WaitUntil(Instant::now() + std::time::Duration::from_millis(100))
                } else {
                    ControlFlow::Wait
                });
            } else {
                el.set_control_flow(ControlFlow::Poll);
                r.window.request_redraw();
            }
        }
    }
}
