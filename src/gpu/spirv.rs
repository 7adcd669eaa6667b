//! The interface a shader declares, read from its SPIR-V: the descriptor type at each binding of
//! set 0 and the size of its push-constant block.
//!
//! A pipeline states its bindings once, in Rust; the shader states them once, in GLSL. This
//! reflection is the check that the two agree: [`check`] runs on every pipeline creation, so a
//! binding given at the wrong slot, with the wrong descriptor type, a binding the shader lacks,
//! or a push-constant type of another size is an error naming the pipeline and the slot, not a
//! validation message (or silent garbage) at draw time.

use ash::vk;
use std::collections::BTreeMap;

/// What one shader stage (or all stages of a pipeline, merged) declares.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Interface {
    /// Descriptor type per binding of set 0.
    pub bindings: BTreeMap<u32, vk::DescriptorType>,
    /// Bytes of the push-constant block (0 without one).
    pub push_bytes: u32,
}

// Opcodes, decorations, storage classes and dimensions used below (SPIR-V 1.x spec, 3.x).
const OP_MEMBER_NAME: u32 = 6;
const OP_TYPE_INT: u32 = 21;
const OP_TYPE_FLOAT: u32 = 22;
const OP_TYPE_VECTOR: u32 = 23;
const OP_TYPE_MATRIX: u32 = 24;
const OP_TYPE_IMAGE: u32 = 25;
const OP_TYPE_SAMPLER: u32 = 26;
const OP_TYPE_SAMPLED_IMAGE: u32 = 27;
const OP_TYPE_ARRAY: u32 = 28;
const OP_TYPE_STRUCT: u32 = 30;
const OP_TYPE_POINTER: u32 = 32;
const OP_CONSTANT: u32 = 43;
const OP_VARIABLE: u32 = 59;
const OP_DECORATE: u32 = 71;
const OP_MEMBER_DECORATE: u32 = 72;
const DEC_BLOCK: u32 = 2;
const DEC_BUFFER_BLOCK: u32 = 3;
const DEC_ARRAY_STRIDE: u32 = 6;
const DEC_MATRIX_STRIDE: u32 = 7;
const DEC_BINDING: u32 = 33;
const DEC_DESCRIPTOR_SET: u32 = 34;
const DEC_OFFSET: u32 = 35;
const SC_UNIFORM_CONSTANT: u32 = 0;
const SC_UNIFORM: u32 = 2;
const SC_PUSH_CONSTANT: u32 = 9;
const SC_STORAGE_BUFFER: u32 = 12;
const DIM_BUFFER: u32 = 5;

#[derive(Debug, Clone)]
enum Type {
    Scalar(u32),
    Vector(u32, u32),
    Matrix(u32, u32),
    Image {
        dim: u32,
        sampled: u32,
    },
    Sampler,
    SampledImage(u32),
    Array(u32, u32),
    Struct(Vec<u32>),
    /// A pointer's pointee (its storage class is the variable's).
    Pointer(u32),
}

#[derive(Default)]
struct Module {
    types: BTreeMap<u32, Type>,
    constants: BTreeMap<u32, u32>,
    /// (id, decoration) -> first literal (or 1 for decorations without one).
    decorations: BTreeMap<(u32, u32), u32>,
    /// (struct, member, decoration) -> first literal.
    member_decorations: BTreeMap<(u32, u32, u32), u32>,
    /// (variable, pointer type, storage class).
    variables: Vec<(u32, u32, u32)>,
    /// (struct, member) -> name.
    member_names: BTreeMap<(u32, u32), String>,
}

impl Module {
    fn parse(spv: &[u8]) -> Result<Module, String> {
        if !spv.len().is_multiple_of(4) || spv.len() < 20 {
            return Err(format!(
                "{} bytes are not a SPIR-V module (a whole number of words, 5 or more)",
                spv.len()
            ));
        }
        let words: Vec<u32> = spv
            .chunks_exact(4)
            .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
            .collect();
        if words[0] != 0x0723_0203 {
            return Err(format!(
                "magic number {:#x} is not SPIR-V's (little-endian)",
                words[0]
            ));
        }
        let mut m = Module::default();
        let mut at = 5;
        while at < words.len() {
            let count = (words[at] >> 16) as usize;
            let op = words[at] & 0xffff;
            if count == 0 || at + count > words.len() {
                return Err(format!(
                    "instruction at word {at} runs past the module's end"
                ));
            }
            let a = &words[at + 1..at + count];
            let arg = |i: usize| a.get(i).copied().unwrap_or(0);
            match op {
                OP_TYPE_INT | OP_TYPE_FLOAT => {
                    m.types.insert(arg(0), Type::Scalar(arg(1) / 8));
                }
                OP_TYPE_VECTOR => {
                    m.types.insert(arg(0), Type::Vector(arg(1), arg(2)));
                }
                OP_TYPE_MATRIX => {
                    m.types.insert(arg(0), Type::Matrix(arg(1), arg(2)));
                }
                OP_TYPE_IMAGE => {
                    m.types.insert(
                        arg(0),
                        Type::Image {
                            dim: arg(2),
                            sampled: arg(6),
                        },
                    );
                }
                OP_TYPE_SAMPLER => {
                    m.types.insert(arg(0), Type::Sampler);
                }
                OP_TYPE_SAMPLED_IMAGE => {
                    m.types.insert(arg(0), Type::SampledImage(arg(1)));
                }
                OP_TYPE_ARRAY => {
                    m.types.insert(arg(0), Type::Array(arg(1), arg(2)));
                }
                OP_TYPE_STRUCT => {
                    m.types.insert(arg(0), Type::Struct(a[1..].to_vec()));
                }
                OP_TYPE_POINTER => {
                    m.types.insert(arg(0), Type::Pointer(arg(2)));
                }
                OP_CONSTANT => {
                    m.constants.insert(arg(1), arg(2));
                }
                OP_VARIABLE => m.variables.push((arg(1), arg(0), arg(2))),
                OP_DECORATE => {
                    m.decorations
                        .insert((arg(0), arg(1)), a.get(2).copied().unwrap_or(1));
                }
                OP_MEMBER_DECORATE => {
                    m.member_decorations
                        .insert((arg(0), arg(1), arg(2)), a.get(3).copied().unwrap_or(1));
                }
                OP_MEMBER_NAME => {
                    let bytes: Vec<u8> = a
                        .get(2..)
                        .unwrap_or(&[])
                        .iter()
                        .flat_map(|w| w.to_le_bytes())
                        .take_while(|&b| b != 0)
                        .collect();
                    m.member_names.insert(
                        (arg(0), arg(1)),
                        String::from_utf8_lossy(&bytes).into_owned(),
                    );
                }
                _ => {}
            }
            at += count;
        }
        Ok(m)
    }

    fn ty(&self, id: u32) -> Result<&Type, String> {
        self.types
            .get(&id)
            .ok_or_else(|| format!("type %{id} is not declared"))
    }

    /// Bytes of a type inside a block (`matrix_stride` from the member that holds it).
    fn size(&self, id: u32, matrix_stride: Option<u32>) -> Result<u32, String> {
        Ok(match self.ty(id)? {
            Type::Scalar(bytes) => *bytes,
            Type::Vector(c, n) => self.size(*c, None)? * n,
            Type::Matrix(col, n) => match matrix_stride {
                Some(stride) => stride * n,
                None => self.size(*col, None)? * n,
            },
            Type::Array(e, len) => {
                let len = self
                    .constants
                    .get(len)
                    .copied()
                    .ok_or_else(|| format!("array length %{len} is not a constant"))?;
                match self.decorations.get(&(id, DEC_ARRAY_STRIDE)) {
                    Some(stride) => stride * len,
                    None => self.size(*e, matrix_stride)? * len,
                }
            }
            Type::Struct(members) => {
                let mut end = 0;
                for (i, &member) in members.iter().enumerate() {
                    let i = i as u32;
                    let offset = self
                        .member_decorations
                        .get(&(id, i, DEC_OFFSET))
                        .copied()
                        .unwrap_or(0);
                    let stride = self
                        .member_decorations
                        .get(&(id, i, DEC_MATRIX_STRIDE))
                        .copied();
                    end = end.max(offset + self.size(member, stride)?);
                }
                end
            }
            other => return Err(format!("type {other:?} has no size in a block")),
        })
    }

    fn descriptor_type(&self, pointee: u32, class: u32) -> Result<vk::DescriptorType, String> {
        let image = |dim: u32, sampled: u32| match (dim == DIM_BUFFER, sampled) {
            (true, 2) => vk::DescriptorType::STORAGE_TEXEL_BUFFER,
            (true, _) => vk::DescriptorType::UNIFORM_TEXEL_BUFFER,
            (false, 2) => vk::DescriptorType::STORAGE_IMAGE,
            (false, _) => vk::DescriptorType::SAMPLED_IMAGE,
        };
        Ok(match (self.ty(pointee)?, class) {
            (Type::Array(e, _), _) => self.descriptor_type(*e, class)?,
            (Type::Image { dim, sampled }, SC_UNIFORM_CONSTANT) => image(*dim, *sampled),
            (Type::Sampler, SC_UNIFORM_CONSTANT) => vk::DescriptorType::SAMPLER,
            (Type::SampledImage(i), SC_UNIFORM_CONSTANT) => match self.ty(*i)? {
                Type::Image { dim, .. } if *dim == DIM_BUFFER => {
                    vk::DescriptorType::UNIFORM_TEXEL_BUFFER
                }
                _ => vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
            },
            (Type::Struct(_), SC_UNIFORM) => {
                if self.decorations.contains_key(&(pointee, DEC_BUFFER_BLOCK)) {
                    vk::DescriptorType::STORAGE_BUFFER
                } else if self.decorations.contains_key(&(pointee, DEC_BLOCK)) {
                    vk::DescriptorType::UNIFORM_BUFFER
                } else {
                    return Err(format!("uniform struct %{pointee} is not a block"));
                }
            }
            (Type::Struct(_), SC_STORAGE_BUFFER) => vk::DescriptorType::STORAGE_BUFFER,
            (t, class) => {
                return Err(format!(
                    "a {t:?} in storage class {class} is not a descriptor this renderer binds"
                ))
            }
        })
    }
}

/// The bindings of set 0 and the push-constant size one SPIR-V module declares.
pub fn reflect(spv: &[u8]) -> Result<Interface, String> {
    let m = Module::parse(spv)?;
    let mut out = Interface::default();
    for &(var, pointer, class) in &m.variables {
        let pointee = match m.ty(pointer)? {
            Type::Pointer(pointee) => *pointee,
            other => return Err(format!("variable %{var} has type {other:?}, not a pointer")),
        };
        if class == SC_PUSH_CONSTANT {
            out.push_bytes = out.push_bytes.max(m.size(pointee, None)?);
            continue;
        }
        let Some(&binding) = m.decorations.get(&(var, DEC_BINDING)) else {
            continue; // inputs, outputs, workgroup and function variables
        };
        let set = m
            .decorations
            .get(&(var, DEC_DESCRIPTOR_SET))
            .copied()
            .unwrap_or(0);
        if set != 0 {
            return Err(format!(
                "binding {binding} is in descriptor set {set}; pipelines here have set 0 only"
            ));
        }
        out.bindings
            .insert(binding, m.descriptor_type(pointee, class)?);
    }
    Ok(out)
}

/// One member of a block as a shader lays it out: name, byte offset, bytes, and the members of
/// a struct it holds (of its elements, for an array of structs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Member {
    /// The member's name in the shader.
    pub name: String,
    /// Byte offset in its block or struct.
    pub offset: u32,
    /// Bytes (an array's: all its elements with their stride).
    pub size: u32,
    /// The members of the struct it is (or whose array it is); empty otherwise.
    pub members: Vec<Member>,
}

/// The members of the uniform or storage block bound at `binding` of set 0 in `spv`, in order:
/// what a Rust struct that mirrors the block is checked against, member by member.
pub fn block_layout(spv: &[u8], binding: u32) -> Result<Vec<Member>, String> {
    let m = Module::parse(spv)?;
    for &(var, pointer, _) in &m.variables {
        if m.decorations.get(&(var, DEC_BINDING)) != Some(&binding)
            || m.decorations.get(&(var, DEC_DESCRIPTOR_SET)).unwrap_or(&0) != &0
        {
            continue;
        }
        let Type::Pointer(pointee) = m.ty(pointer)? else {
            return Err(format!("variable %{var} is not a pointer"));
        };
        return m.members(*pointee);
    }
    Err(format!("no block is bound at binding {binding}"))
}

impl Module {
    fn members(&self, id: u32) -> Result<Vec<Member>, String> {
        let Type::Struct(types) = self.ty(id)? else {
            return Err(format!("type %{id} is not a struct"));
        };
        types
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                let i = i as u32;
                let stride = self
                    .member_decorations
                    .get(&(id, i, DEC_MATRIX_STRIDE))
                    .copied();
                let inner = match self.ty(t)? {
                    Type::Struct(_) => self.members(t)?,
                    Type::Array(e, _) if matches!(self.ty(*e)?, Type::Struct(_)) => {
                        self.members(*e)?
                    }
                    _ => Vec::new(),
                };
                Ok(Member {
                    name: self.member_names.get(&(id, i)).cloned().unwrap_or_default(),
                    offset: self
                        .member_decorations
                        .get(&(id, i, DEC_OFFSET))
                        .copied()
                        .unwrap_or(0),
                    size: self.size(t, stride)?,
                    members: inner,
                })
            })
            .collect()
    }
}

/// The interface of a pipeline whose stages are `modules` (their bindings merged; a binding
/// declared with two types is an error).
pub fn reflect_stages(modules: &[&[u8]]) -> Result<Interface, String> {
    let mut out = Interface::default();
    for spv in modules {
        let i = reflect(spv)?;
        out.push_bytes = out.push_bytes.max(i.push_bytes);
        for (slot, ty) in i.bindings {
            if let Some(other) = out.bindings.insert(slot, ty) {
                if other != ty {
                    return Err(format!(
                        "binding {slot} is a {other:?} in one stage and a {ty:?} in another"
                    ));
                }
            }
        }
    }
    Ok(out)
}

/// Checks what a pipeline binds and pushes (`given`) against what its shaders declare: every
/// declared binding given with its type, nothing given that the shaders do not declare, and a
/// push-constant type of the block's size. The message names the slot.
pub fn check(declared: &Interface, given: &Interface) -> Result<(), String> {
    for (slot, ty) in &declared.bindings {
        match given.bindings.get(slot) {
            None => {
                return Err(format!(
                    "the shader reads a {ty:?} at binding {slot}, which is not bound"
                ))
            }
            Some(g) if g != ty => {
                return Err(format!(
                    "binding {slot} is bound as a {g:?} but the shader declares a {ty:?}"
                ))
            }
            Some(_) => {}
        }
    }
    if let Some((slot, ty)) = given
        .bindings
        .iter()
        .find(|(s, _)| !declared.bindings.contains_key(s))
    {
        return Err(format!(
            "a {ty:?} is bound at binding {slot}, which the shader does not declare"
        ));
    }
    if declared.push_bytes != given.push_bytes {
        return Err(format!(
            "push constants of {} bytes for the shader's {}-byte block",
            given.push_bytes, declared.push_bytes
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::shaders;

    #[test]
    fn every_shader_reflects() {
        // The light-entry image's fragment shader reads only what the vertex shader passes
        // it; every other shader has bindings or push constants.
        for (name, spv) in shaders::ALL {
            let i = reflect(spv).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(
                !i.bindings.is_empty() || i.push_bytes > 0,
                *name != "shadow.frag",
                "{name}: bindings {:?}, push constants of {} bytes",
                i.bindings,
                i.push_bytes
            );
        }
    }

    #[test]
    fn local_comp_declares_its_six_bindings_and_two_words() {
        let i = reflect(shaders::LOCAL_COMP).unwrap();
        use vk::DescriptorType as D;
        let want: BTreeMap<u32, D> = [
            (0, D::UNIFORM_TEXEL_BUFFER),
            (1, D::UNIFORM_TEXEL_BUFFER),
            (2, D::STORAGE_IMAGE),
            (3, D::STORAGE_IMAGE),
            (4, D::UNIFORM_TEXEL_BUFFER),
            (5, D::UNIFORM_TEXEL_BUFFER),
        ]
        .into();
        assert_eq!(i.bindings, want);
        assert_eq!(i.push_bytes, 8);
    }

    #[test]
    fn stages_merge_and_blocks_have_their_sizes() {
        use vk::DescriptorType as D;
        let composite =
            reflect_stages(&[shaders::COMPOSITE_VERT, shaders::COMPOSITE_FRAG]).unwrap();
        assert_eq!(composite.bindings[&0], D::UNIFORM_BUFFER);
        assert_eq!(composite.bindings[&3], D::COMBINED_IMAGE_SAMPLER);
        assert_eq!(composite.push_bytes, 4);
        assert_eq!(reflect(shaders::ILLUM_VERT).unwrap().push_bytes, 8);
        let ssbo = reflect(shaders::GLOBAL_SSBO_COMP).unwrap();
        assert_eq!(ssbo.bindings[&0], D::STORAGE_BUFFER);
        assert_eq!(ssbo.bindings[&3], D::STORAGE_TEXEL_BUFFER);
    }

    #[test]
    fn mismatches_name_the_slot() {
        use vk::DescriptorType as D;
        let declared = reflect(shaders::DILATE_COMP).unwrap();
        let mut given = declared.clone();
        assert_eq!(check(&declared, &given), Ok(()));
        given.bindings.insert(1, D::STORAGE_IMAGE);
        let e = check(&declared, &given).unwrap_err();
        assert!(
            e.contains("binding 1") && e.contains("STORAGE_IMAGE"),
            "{e}"
        );
        let mut missing = declared.clone();
        missing.bindings.remove(&2);
        assert!(check(&declared, &missing)
            .unwrap_err()
            .contains("binding 2"));
        let mut extra = declared.clone();
        extra.bindings.insert(7, D::UNIFORM_BUFFER);
        assert!(check(&declared, &extra).unwrap_err().contains("binding 7"));
        let mut push = declared.clone();
        push.push_bytes = 8;
        assert!(check(&declared, &push).unwrap_err().contains("8 bytes"));
        assert!(reflect(&[0u8; 20]).is_err());
        let mut overlong = shaders::DILATE_COMP.to_vec();
        overlong[22..24].copy_from_slice(&0xffffu16.to_le_bytes()); // first instruction's count
        assert!(reflect(&overlong).unwrap_err().contains("runs past"));
    }
}
