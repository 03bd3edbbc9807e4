//! Steady-state frames allocate nothing: a test crate of its own, since it
//! installs a counting global allocator (a test binary has one). Its tests run
//! one at a time (`counting_alloc::serial`), so one test's allocations are never
//! counted in another's.

mod counting_alloc;
mod no_alloc;
mod rle_no_alloc;
