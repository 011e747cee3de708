//! (Skeleton: being implemented.)
