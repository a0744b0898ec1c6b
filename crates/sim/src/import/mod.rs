//! Worlds written from another project's files. An importer reads a copy the user has and
//! writes a world folder that points at those files (nothing is copied: the sources' licences
//! are theirs); the folder's `assets` names the copy, and nothing in the world's hash depends
//! on where either lies.

pub mod csv;
pub mod dexmobile;
mod svh;
