//! Graph compilation: pass ordering and barrier derivation. Pure code, no GPU.
//!
//! Semantics of a frame graph here (declaration order defines the data flow):
//! - Passes that write a resource run in the order they were declared (write-after-write).
//! - A read sees the last write declared before it (read-after-write); a later write waits
//!   for it (write-after-read).
//! - A read declared before any write sees, for an imported resource, its contents at the
//!   start of the frame; for a transient resource, the first write, wherever that pass was
//!   declared. So a consumer may be declared before its producer and the graph reorders them.
//! - Among passes free to run, the one declared first runs first.
//! - A transient resource read by a pass must be written by some pass of the graph.
//! - Barriers follow from each resource's previous access in the schedule: read-after-write
//!   and write-after-write get a memory dependency, write-after-read an execution dependency,
//!   and every image layout change a transition. Reads that a previous barrier already made
//!   the write visible to need none.

use super::access::{Access, AccessInfo};
use ash::vk;
use std::collections::BTreeSet;

/// Index of a resource in the graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ResourceId(pub usize);

/// Image or buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResourceKind {
    /// A 2D image (possibly layered).
    Image,
    /// A buffer.
    Buffer,
}

/// What compilation needs to know of a resource.
#[derive(Debug, Clone)]
pub struct ResourceDecl {
    /// Name (for messages and debug labels).
    pub name: String,
    /// Image or buffer.
    pub kind: ResourceKind,
    /// Imported resources live outside the graph and hold data before the frame starts;
    /// transient ones are created by the graph and start each frame undefined.
    pub imported: bool,
    /// Layout an imported image is in when the frame starts.
    pub initial_layout: vk::ImageLayout,
    /// Access the resource must be ready for after the frame (e.g. host reads).
    pub export: Option<Access>,
}

/// What compilation needs to know of a pass.
#[derive(Debug, Clone)]
pub struct PassDecl {
    /// Name: debug label, timing scope and report key.
    pub name: String,
    /// Every resource the pass touches, once each, with how.
    pub accesses: Vec<(ResourceId, Access)>,
}

/// One derived barrier.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Barrier {
    /// The resource it guards.
    pub resource: ResourceId,
    /// Stages that must finish first.
    pub src_stages: vk::PipelineStageFlags2,
    /// Writes to make available.
    pub src_access: vk::AccessFlags2,
    /// Stages that wait.
    pub dst_stages: vk::PipelineStageFlags2,
    /// Accesses the data is made visible to.
    pub dst_access: vk::AccessFlags2,
    /// Layout before (images).
    pub old_layout: vk::ImageLayout,
    /// Layout after (images).
    pub new_layout: vk::ImageLayout,
}

/// The result of compilation.
#[derive(Debug, Clone)]
pub struct Schedule {
    /// Pass indices (declaration order numbers) in execution order.
    pub order: Vec<usize>,
    /// Barriers to issue before each scheduled pass, parallel to `order`.
    pub barriers: Vec<Vec<Barrier>>,
    /// Barriers after the last pass, for exported resources.
    pub final_barriers: Vec<Barrier>,
}

/// Why a graph cannot be compiled.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GraphError {
    /// A pass lists the same resource twice.
    #[error(
        "pass '{pass}' declares resource '{resource}' more than once; use one combined access"
    )]
    DuplicateAccess {
        /// The pass.
        pass: String,
        /// The resource.
        resource: String,
    },
    /// An access type that does not apply to the resource's kind.
    #[error("pass '{pass}' declares {access:?} on {kind:?} '{resource}', which does not apply")]
    InvalidAccess {
        /// The pass.
        pass: String,
        /// The resource.
        resource: String,
        /// The access.
        access: Access,
        /// The resource kind.
        kind: ResourceKind,
    },
    /// Leaving out a pass would leave an image in another layout than a later barrier expects.
    #[error("pass '{pass}' cannot be skipped: it changes the layout of '{resource}', which a later pass of the frame expects")]
    UnsafeSkip {
        /// The skipped pass.
        pass: String,
        /// The image.
        resource: String,
    },
    /// A transient resource is read but nothing writes it.
    #[error("pass '{pass}' reads transient resource '{resource}', which no pass writes")]
    ReadWithoutWriter {
        /// The pass.
        pass: String,
        /// The resource.
        resource: String,
    },
    /// A pass binds a resource it did not declare, or declared with an unfitting access.
    #[error(
        "pass '{pass}' binds resource '{resource}' at slot {slot} as {kind:?}, but {}",
        match declared {
            None => "does not declare it (add an .access(...) for it)".to_string(),
            Some(a) => format!("declares it {a:?}, which does not admit that binding"),
        }
    )]
    Binding {
        /// The pass.
        pass: String,
        /// The resource.
        resource: String,
        /// The shader slot (`binding = N`).
        slot: u32,
        /// What the pass binds it as.
        kind: super::BindKind,
        /// What the pass declared, if anything.
        declared: Option<Access>,
    },
    /// The passes' dependencies form a cycle.
    #[error("passes depend on each other in a cycle: {0:?}")]
    Cycle(Vec<String>),
    /// Two passes share a name.
    #[error("two passes are named '{0}'; pass names key the timing report and must be unique")]
    DuplicatePassName(String),
    /// A resource id outside the graph.
    #[error("pass '{pass}' uses a resource id {id} that the graph does not have")]
    UnknownResource {
        /// The pass.
        pass: String,
        /// The bad id.
        id: usize,
    },
}

fn validate(resources: &[ResourceDecl], passes: &[PassDecl]) -> Result<(), GraphError> {
    let mut names = BTreeSet::new();
    for p in passes {
        if !names.insert(p.name.as_str()) {
            return Err(GraphError::DuplicatePassName(p.name.clone()));
        }
        let mut seen = BTreeSet::new();
        for (r, a) in &p.accesses {
            let Some(res) = resources.get(r.0) else {
                return Err(GraphError::UnknownResource {
                    pass: p.name.clone(),
                    id: r.0,
                });
            };
            if !seen.insert(*r) {
                return Err(GraphError::DuplicateAccess {
                    pass: p.name.clone(),
                    resource: res.name.clone(),
                });
            }
            let ok = match res.kind {
                ResourceKind::Image => a.valid_for_image(),
                ResourceKind::Buffer => a.valid_for_buffer(),
            };
            if !ok {
                return Err(GraphError::InvalidAccess {
                    pass: p.name.clone(),
                    resource: res.name.clone(),
                    access: *a,
                    kind: res.kind,
                });
            }
        }
    }
    Ok(())
}

/// Orders the passes (see the module documentation for the rules).
pub fn order_passes(
    resources: &[ResourceDecl],
    passes: &[PassDecl],
) -> Result<Vec<usize>, GraphError> {
    validate(resources, passes)?;
    let n = passes.len();
    let mut edges: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); n];
    let mut edge = |from: usize, to: usize| {
        if from != to {
            edges[from].insert(to);
        }
    };
    for (rid, res) in resources.iter().enumerate() {
        let uses: Vec<(usize, bool)> = passes
            .iter()
            .enumerate()
            .flat_map(|(pi, p)| {
                p.accesses
                    .iter()
                    .filter(move |(r, _)| r.0 == rid)
                    .map(move |(_, a)| (pi, a.info().writes))
            })
            .collect();
        let first_writer = uses.iter().find(|(_, w)| *w).map(|(p, _)| *p);
        let mut last_writer: Option<usize> = None;
        let mut readers: Vec<usize> = Vec::new();
        let mut early_readers: Vec<usize> = Vec::new();
        for (p, writes) in uses {
            if writes {
                if let Some(w) = last_writer {
                    edge(w, p);
                }
                for &q in &readers {
                    edge(q, p);
                }
                readers = if last_writer.is_none() {
                    std::mem::take(&mut early_readers)
                } else {
                    Vec::new()
                };
                last_writer = Some(p);
            } else {
                match (last_writer, res.imported, first_writer) {
                    (Some(w), _, _) => {
                        edge(w, p);
                        readers.push(p);
                    }
                    (None, true, _) => readers.push(p),
                    (None, false, Some(w)) => {
                        edge(w, p);
                        early_readers.push(p);
                    }
                    (None, false, None) => {
                        return Err(GraphError::ReadWithoutWriter {
                            pass: passes[p].name.clone(),
                            resource: res.name.clone(),
                        })
                    }
                }
            }
        }
    }
    let mut indegree = vec![0usize; n];
    for e in &edges {
        for &t in e {
            indegree[t] += 1;
        }
    }
    let mut ready: BTreeSet<usize> = (0..n).filter(|&i| indegree[i] == 0).collect();
    let mut order = Vec::with_capacity(n);
    while let Some(&next) = ready.iter().next() {
        ready.remove(&next);
        order.push(next);
        for &t in &edges[next] {
            indegree[t] -= 1;
            if indegree[t] == 0 {
                ready.insert(t);
            }
        }
    }
    if order.len() != n {
        let stuck = (0..n)
            .filter(|i| !order.contains(i))
            .map(|i| passes[i].name.clone())
            .collect();
        return Err(GraphError::Cycle(stuck));
    }
    Ok(order)
}

#[derive(Clone, Copy)]
struct State {
    layout: vk::ImageLayout,
    last_write: Option<AccessInfo>,
    visible_stages: vk::PipelineStageFlags2,
    visible_access: vk::AccessFlags2,
    read_stages: vk::PipelineStageFlags2,
}

impl State {
    fn new(decl: &ResourceDecl) -> State {
        State {
            layout: if decl.imported {
                decl.initial_layout
            } else {
                vk::ImageLayout::UNDEFINED
            },
            last_write: None,
            visible_stages: vk::PipelineStageFlags2::empty(),
            visible_access: vk::AccessFlags2::empty(),
            read_stages: vk::PipelineStageFlags2::empty(),
        }
    }

    /// The barrier (if any) needed before `next`, and the state after it.
    fn transition(
        &mut self,
        resource: ResourceId,
        kind: ResourceKind,
        next: AccessInfo,
    ) -> Option<Barrier> {
        let is_image = kind == ResourceKind::Image;
        let layout_change = is_image && self.layout != next.layout;
        let new_layout = if is_image {
            next.layout
        } else {
            vk::ImageLayout::UNDEFINED
        };
        let old_layout = if is_image {
            self.layout
        } else {
            vk::ImageLayout::UNDEFINED
        };
        let barrier = if next.writes || layout_change {
            // The write (or the layout transition, itself a write) must wait for everything
            // that touched the resource since its last write.
            let (src_stages, src_access) = if !self.read_stages.is_empty() {
                (self.read_stages, vk::AccessFlags2::NONE)
            } else if let Some(w) = self.last_write {
                (w.stages, w.access & WRITE_BITS)
            } else {
                (vk::PipelineStageFlags2::NONE, vk::AccessFlags2::NONE)
            };
            let needed = layout_change || src_stages != vk::PipelineStageFlags2::NONE;
            needed.then_some(Barrier {
                resource,
                src_stages,
                src_access,
                dst_stages: next.stages,
                dst_access: next.access,
                old_layout,
                new_layout,
            })
        } else if let Some(w) = self.last_write {
            let covered = self.visible_stages.contains(next.stages)
                && self.visible_access.contains(next.access);
            (!covered).then_some(Barrier {
                resource,
                src_stages: w.stages,
                src_access: w.access & WRITE_BITS,
                dst_stages: next.stages,
                dst_access: next.access,
                old_layout,
                new_layout,
            })
        } else {
            None
        };
        if next.writes {
            self.last_write = Some(next);
            self.visible_stages = vk::PipelineStageFlags2::empty();
            self.visible_access = vk::AccessFlags2::empty();
            self.read_stages = vk::PipelineStageFlags2::empty();
        } else {
            if barrier.is_some() {
                self.visible_stages |= next.stages;
                self.visible_access |= next.access;
            }
            self.read_stages |= next.stages;
        }
        if is_image {
            self.layout = next.layout;
        }
        barrier
    }
}

const WRITE_BITS: vk::AccessFlags2 = vk::AccessFlags2::from_raw(
    vk::AccessFlags2::SHADER_STORAGE_WRITE.as_raw()
        | vk::AccessFlags2::COLOR_ATTACHMENT_WRITE.as_raw()
        | vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE.as_raw()
        | vk::AccessFlags2::TRANSFER_WRITE.as_raw()
        | vk::AccessFlags2::HOST_WRITE.as_raw()
        | vk::AccessFlags2::MEMORY_WRITE.as_raw(),
);

/// Orders the passes and derives every barrier and layout transition.
pub fn compile(resources: &[ResourceDecl], passes: &[PassDecl]) -> Result<Schedule, GraphError> {
    let order = order_passes(resources, passes)?;
    let mut states: Vec<State> = resources.iter().map(State::new).collect();
    let mut barriers = Vec::with_capacity(order.len());
    for &pi in &order {
        let mut pass_barriers = Vec::new();
        for (r, a) in &passes[pi].accesses {
            if let Some(b) = states[r.0].transition(*r, resources[r.0].kind, a.info()) {
                pass_barriers.push(b);
            }
        }
        barriers.push(pass_barriers);
    }
    let mut final_barriers = Vec::new();
    for (i, res) in resources.iter().enumerate() {
        if let Some(export) = res.export {
            if let Some(b) = states[i].transition(ResourceId(i), res.kind, export.info()) {
                final_barriers.push(b);
            }
        }
    }
    Ok(Schedule {
        order,
        barriers,
        final_barriers,
    })
}

/// Checks that running only the scheduled passes with `ran[i]` true (in schedule order) keeps
/// every image layout transition valid: each barrier that runs, and each final barrier, must
/// start from the layout the image is really in (or from `UNDEFINED`, which discards). A
/// skipped pass's barriers do not run, so a pass that moves an image into a layout a later pass
/// starts from cannot be skipped.
pub fn check_skip(
    resources: &[ResourceDecl],
    pass_names: &[&str],
    schedule: &Schedule,
    ran: &[bool],
) -> Result<(), GraphError> {
    let mut layout: Vec<vk::ImageLayout> = resources.iter().map(|r| r.initial_layout).collect();
    // Who last changed each layout, for the message.
    let mut changed_by: Vec<Option<usize>> = vec![None; resources.len()];
    let mut full: Vec<vk::ImageLayout> = layout.clone();
    let check = |b: &Barrier, layout: &mut Vec<vk::ImageLayout>, changed_by: &[Option<usize>]| {
        let r = b.resource.0;
        if resources[r].kind != ResourceKind::Image {
            return Ok(());
        }
        if b.old_layout != vk::ImageLayout::UNDEFINED && b.old_layout != layout[r] {
            return Err(GraphError::UnsafeSkip {
                pass: changed_by[r]
                    .map(|p| pass_names[p].to_string())
                    .unwrap_or_default(),
                resource: resources[r].name.clone(),
            });
        }
        layout[r] = b.new_layout;
        Ok(())
    };
    for (i, barriers) in schedule.barriers.iter().enumerate() {
        for b in barriers {
            let r = b.resource.0;
            if resources[r].kind == ResourceKind::Image {
                if ran[i] {
                    check(b, &mut layout, &changed_by)?;
                } else if full[r] != b.new_layout {
                    // The full schedule would have moved it here; remember who.
                    changed_by[r] = Some(schedule.order[i]);
                }
                full[r] = b.new_layout;
            }
        }
    }
    for b in &schedule.final_barriers {
        check(b, &mut layout, &changed_by)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::access::Stage;
    use super::*;
    use vk::AccessFlags2 as A;
    use vk::ImageLayout as L;
    use vk::PipelineStageFlags2 as S;

    fn image(name: &str) -> ResourceDecl {
        ResourceDecl {
            name: name.into(),
            kind: ResourceKind::Image,
            imported: false,
            initial_layout: L::UNDEFINED,
            export: None,
        }
    }

    fn buffer(name: &str, imported: bool) -> ResourceDecl {
        ResourceDecl {
            name: name.into(),
            kind: ResourceKind::Buffer,
            imported,
            initial_layout: L::UNDEFINED,
            export: None,
        }
    }

    fn pass(name: &str, accesses: &[(usize, Access)]) -> PassDecl {
        PassDecl {
            name: name.into(),
            accesses: accesses.iter().map(|(r, a)| (ResourceId(*r), *a)).collect(),
        }
    }

    #[test]
    fn orders_readers_after_writers_whatever_the_declaration_order() {
        let res = [image("shadow"), image("hdr"), image("ldr")];
        let passes = [
            pass(
                "tonemap",
                &[
                    (1, Access::StorageRead(Stage::Compute)),
                    (2, Access::StorageWrite(Stage::Compute)),
                ],
            ),
            pass(
                "shade",
                &[
                    (0, Access::Sampled(Stage::Fragment)),
                    (1, Access::ColorAttachment),
                ],
            ),
            pass("shadow", &[(0, Access::DepthAttachment)]),
        ];
        let order = order_passes(&res, &passes).unwrap();
        assert_eq!(order, vec![2, 1, 0]);
    }

    #[test]
    fn independent_passes_keep_declaration_order() {
        let res = [image("a"), image("b")];
        let passes = [
            pass("first", &[(0, Access::ColorAttachment)]),
            pass("second", &[(1, Access::ColorAttachment)]),
        ];
        assert_eq!(order_passes(&res, &passes).unwrap(), vec![0, 1]);
    }

    #[test]
    fn detects_cycles_and_bad_declarations() {
        let res = [image("a"), image("b")];
        let passes = [
            pass(
                "p",
                &[
                    (0, Access::StorageWrite(Stage::Compute)),
                    (1, Access::Sampled(Stage::Compute)),
                ],
            ),
            pass(
                "q",
                &[
                    (1, Access::StorageWrite(Stage::Compute)),
                    (0, Access::Sampled(Stage::Compute)),
                ],
            ),
        ];
        assert!(matches!(compile(&res, &passes), Err(GraphError::Cycle(_))));
        let dup = [pass(
            "p",
            &[
                (0, Access::ColorAttachment),
                (0, Access::Sampled(Stage::Fragment)),
            ],
        )];
        assert!(matches!(
            compile(&res, &dup),
            Err(GraphError::DuplicateAccess { .. })
        ));
        let bad = [pass("p", &[(0, Access::VertexBuffer)])];
        assert!(matches!(
            compile(&res, &bad),
            Err(GraphError::InvalidAccess { .. })
        ));
        let orphan = [pass("p", &[(0, Access::Sampled(Stage::Fragment))])];
        assert!(matches!(
            compile(&res, &orphan),
            Err(GraphError::ReadWithoutWriter { .. })
        ));
        let twice = [
            pass("p", &[(0, Access::ColorAttachment)]),
            pass("p", &[(1, Access::ColorAttachment)]),
        ];
        assert!(matches!(
            compile(&res, &twice),
            Err(GraphError::DuplicatePassName(_))
        ));
        let unknown = [pass("p", &[(9, Access::ColorAttachment)])];
        assert!(matches!(
            compile(&res, &unknown),
            Err(GraphError::UnknownResource { .. })
        ));
    }

    #[test]
    fn depth_write_then_sample_transitions_layout_with_memory_dependency() {
        let res = [image("shadow"), image("hdr")];
        let passes = [
            pass("shadow", &[(0, Access::DepthAttachment)]),
            pass(
                "shade",
                &[
                    (0, Access::Sampled(Stage::Fragment)),
                    (1, Access::ColorAttachment),
                ],
            ),
        ];
        let s = compile(&res, &passes).unwrap();
        // First use: UNDEFINED -> DEPTH_ATTACHMENT_OPTIMAL, nothing to wait for.
        assert_eq!(s.barriers[0].len(), 1);
        let b = s.barriers[0][0];
        assert_eq!(
            (b.old_layout, b.new_layout),
            (L::UNDEFINED, L::DEPTH_ATTACHMENT_OPTIMAL)
        );
        assert_eq!(b.src_stages, S::NONE);
        // Read after write: the depth writes are made visible to fragment sampling.
        let b = s.barriers[1]
            .iter()
            .find(|b| b.resource == ResourceId(0))
            .unwrap();
        assert_eq!(
            (b.old_layout, b.new_layout),
            (L::DEPTH_ATTACHMENT_OPTIMAL, L::SHADER_READ_ONLY_OPTIMAL)
        );
        assert_eq!(
            b.src_stages,
            S::EARLY_FRAGMENT_TESTS | S::LATE_FRAGMENT_TESTS
        );
        assert_eq!(b.src_access, A::DEPTH_STENCIL_ATTACHMENT_WRITE);
        assert_eq!(b.dst_stages, S::FRAGMENT_SHADER);
        assert_eq!(b.dst_access, A::SHADER_SAMPLED_READ);
    }

    #[test]
    fn write_after_read_needs_only_an_execution_dependency() {
        // An imported buffer is read by one pass and then overwritten by another.
        let res = [buffer("data", true), buffer("out", false)];
        let passes = [
            pass(
                "read",
                &[
                    (0, Access::TexelRead(Stage::Compute)),
                    (1, Access::StorageWrite(Stage::Compute)),
                ],
            ),
            pass(
                "overwrite",
                &[
                    (1, Access::StorageRead(Stage::Compute)),
                    (0, Access::TransferWrite),
                ],
            ),
        ];
        let s = compile(&res, &passes).unwrap();
        assert_eq!(s.order, vec![0, 1]);
        // The imported buffer's first read needs no barrier: uploads complete before the frame.
        assert!(s.barriers[0].is_empty());
        let war = s.barriers[1]
            .iter()
            .find(|b| b.resource == ResourceId(0))
            .unwrap();
        assert_eq!(war.src_stages, S::COMPUTE_SHADER);
        assert_eq!(war.src_access, A::NONE);
        assert_eq!(war.dst_stages, S::COPY | S::CLEAR);
        assert_eq!(war.dst_access, A::TRANSFER_WRITE);
        // Buffers have no layouts.
        assert_eq!(
            (war.old_layout, war.new_layout),
            (L::UNDEFINED, L::UNDEFINED)
        );
        let raw = s.barriers[1]
            .iter()
            .find(|b| b.resource == ResourceId(1))
            .unwrap();
        assert_eq!(raw.src_access, A::SHADER_STORAGE_WRITE);
        assert_eq!(raw.dst_access, A::SHADER_STORAGE_READ);
    }

    #[test]
    fn repeated_reads_share_one_barrier_and_new_stages_get_their_own() {
        let res = [image("hdr"), image("x"), image("y"), image("z")];
        let passes = [
            pass("draw", &[(0, Access::ColorAttachment)]),
            pass(
                "a",
                &[
                    (0, Access::Sampled(Stage::Fragment)),
                    (1, Access::ColorAttachment),
                ],
            ),
            pass(
                "b",
                &[
                    (0, Access::Sampled(Stage::Fragment)),
                    (2, Access::ColorAttachment),
                ],
            ),
            pass(
                "c",
                &[
                    (0, Access::Sampled(Stage::Compute)),
                    (3, Access::StorageWrite(Stage::Compute)),
                ],
            ),
        ];
        let s = compile(&res, &passes).unwrap();
        let on_hdr = |i: usize| {
            s.barriers[i]
                .iter()
                .filter(|b| b.resource == ResourceId(0))
                .count()
        };
        assert_eq!(on_hdr(1), 1);
        assert_eq!(on_hdr(2), 0, "already visible to fragment sampling");
        assert_eq!(on_hdr(3), 1, "compute sampling needs its own visibility");
        let b = s.barriers[3]
            .iter()
            .find(|b| b.resource == ResourceId(0))
            .unwrap();
        assert_eq!(b.src_access, A::COLOR_ATTACHMENT_WRITE);
        assert_eq!(b.old_layout, b.new_layout);
    }

    #[test]
    fn layout_change_between_reads_waits_for_the_readers() {
        let res = [image("hdr"), image("x"), buffer("readback", true)];
        let passes = [
            pass("draw", &[(0, Access::ColorAttachment)]),
            pass(
                "sample",
                &[
                    (0, Access::Sampled(Stage::Compute)),
                    (1, Access::StorageWrite(Stage::Compute)),
                ],
            ),
            pass(
                "copy",
                &[(0, Access::TransferRead), (2, Access::TransferWrite)],
            ),
        ];
        let s = compile(&res, &passes).unwrap();
        let b = s.barriers[2]
            .iter()
            .find(|b| b.resource == ResourceId(0))
            .unwrap();
        assert_eq!(b.src_stages, S::COMPUTE_SHADER);
        assert_eq!(
            (b.old_layout, b.new_layout),
            (L::SHADER_READ_ONLY_OPTIMAL, L::TRANSFER_SRC_OPTIMAL)
        );
    }

    #[test]
    fn exported_buffer_gets_a_host_read_barrier() {
        let mut rb = buffer("readback", true);
        rb.export = Some(Access::HostRead);
        let res = [image("hdr"), rb];
        let passes = [
            pass("draw", &[(0, Access::ColorAttachment)]),
            pass(
                "copy",
                &[(0, Access::TransferRead), (1, Access::TransferWrite)],
            ),
        ];
        let s = compile(&res, &passes).unwrap();
        assert_eq!(s.final_barriers.len(), 1);
        let b = s.final_barriers[0];
        assert_eq!(b.resource, ResourceId(1));
        assert_eq!(
            (b.src_access, b.dst_stages, b.dst_access),
            (A::TRANSFER_WRITE, S::HOST, A::HOST_READ)
        );
    }

    #[test]
    fn writers_run_in_declaration_order_with_waw_barriers() {
        let res = [image("acc"), buffer("out", true)];
        let passes = [
            pass("clear", &[(0, Access::TransferWrite)]),
            pass(
                "accumulate",
                &[(0, Access::StorageReadWrite(Stage::Compute))],
            ),
            pass(
                "copy",
                &[(0, Access::TransferRead), (1, Access::TransferWrite)],
            ),
        ];
        let s = compile(&res, &passes).unwrap();
        assert_eq!(s.order, vec![0, 1, 2]);
        let b = s.barriers[1][0];
        assert_eq!(b.src_access, A::TRANSFER_WRITE);
        assert_eq!(
            (b.old_layout, b.new_layout),
            (L::TRANSFER_DST_OPTIMAL, L::GENERAL)
        );
        let b = s.barriers[2]
            .iter()
            .find(|b| b.resource == ResourceId(0))
            .unwrap();
        assert_eq!(b.src_access, A::SHADER_STORAGE_WRITE);
    }

    /// An image kept across frames in GENERAL, drawn as a colour attachment in that layout and
    /// read as storage: a colour barrier without a layout change, and the drawing pass may be
    /// skipped; drawn in COLOR_ATTACHMENT_OPTIMAL instead, skipping it is refused.
    #[test]
    fn a_colour_attachment_in_general_layout_can_be_skipped() {
        let kept = |name: &str| ResourceDecl {
            imported: true,
            initial_layout: L::GENERAL,
            ..image(name)
        };
        let res = [kept("entry")];
        let names = ["shadow", "single"];
        let passes = |draw: Access| {
            [
                pass("shadow", &[(0, draw)]),
                pass("single", &[(0, Access::StorageRead(Stage::Compute))]),
            ]
        };
        let s = compile(&res, &passes(Access::ColorAttachmentGeneral)).unwrap();
        assert!(s.barriers[0].is_empty(), "{:?}", s.barriers[0]);
        let b = s.barriers[1][0];
        assert_eq!(
            (b.src_stages, b.dst_stages, b.dst_access),
            (
                S::COLOR_ATTACHMENT_OUTPUT,
                S::COMPUTE_SHADER,
                A::SHADER_STORAGE_READ
            )
        );
        assert!(b.src_access.contains(A::COLOR_ATTACHMENT_WRITE));
        assert_eq!((b.old_layout, b.new_layout), (L::GENERAL, L::GENERAL));
        check_skip(&res, &names, &s, &[false, true]).unwrap();
        let s = compile(&res, &passes(Access::ColorAttachment)).unwrap();
        assert!(matches!(
            check_skip(&res, &names, &s, &[false, true]),
            Err(GraphError::UnsafeSkip { .. })
        ));
    }

    #[test]
    fn skipping_a_pass_that_changes_a_layout_a_later_pass_expects_is_refused() {
        let res = [image("display")];
        let passes = [
            pass("tonemap", &[(0, Access::StorageWrite(Stage::Compute))]),
            pass("readback", &[(0, Access::TransferRead)]),
            pass("overlay", &[(0, Access::StorageRead(Stage::Compute))]),
        ];
        let names = ["tonemap", "readback", "overlay"];
        let s = compile(&res, &passes).unwrap();
        assert_eq!(s.order, vec![0, 1, 2]);
        check_skip(&res, &names, &s, &[true, true, true]).unwrap();
        match check_skip(&res, &names, &s, &[true, false, true]) {
            Err(GraphError::UnsafeSkip { pass, resource }) => {
                assert_eq!((pass.as_str(), resource.as_str()), ("readback", "display"))
            }
            other => panic!("expected UnsafeSkip, got {other:?}"),
        }
        // The last reader changes nothing a later pass relies on.
        check_skip(&res, &names, &s, &[true, true, false]).unwrap();
        // Readback last: skipping it is safe.
        let reordered = [passes[0].clone(), passes[2].clone(), passes[1].clone()];
        let s = compile(&res, &reordered).unwrap();
        check_skip(
            &res,
            &["tonemap", "overlay", "readback"],
            &s,
            &[true, true, false],
        )
        .unwrap();
    }
}
