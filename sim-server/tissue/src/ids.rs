//! Typed indices. Tetrahedra are never renumbered: a removed tetrahedron keeps
//! its slot (marked dead) and adding it back revives the same id, so ids held
//! by tools or scripts never point at a different element.

macro_rules! typed_id {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[repr(transparent)]
        #[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
        pub struct $name(pub u32);

        impl $name {
            /// The id as an index into the owning array.
            #[inline]
            pub fn idx(self) -> usize {
                self.0 as usize
            }
        }

        impl From<usize> for $name {
            #[inline]
            fn from(i: usize) -> Self {
                debug_assert!(i <= u32::MAX as usize);
                Self(i as u32)
            }
        }
    };
}

typed_id!(
    /// A mesh vertex.
    VertexId
);
typed_id!(
    /// A tetrahedron.
    TetId
);
typed_id!(
    /// A mesh edge (an unordered vertex pair that some tetrahedron has or had).
    EdgeId
);
