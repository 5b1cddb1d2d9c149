//! The iceoryx2 service type every agp process uses: iceoryx2's `ipc::Service` with one part
//! changed, measured on the 2-core machine the pipeline was built on.
//!
//! - **No heap allocation per loaned sample**: iceoryx2 0.10 keeps each loan's bookkeeping
//!   behind the service's `ArcThreadSafetyPolicy`, an `Rc` for `ipc::Service`, so every
//!   `loan_uninit` called `malloc`. [`PooledRc`] is the same single-threaded reference count
//!   with its blocks taken from a per-thread free list that only grows: once the pipeline
//!   runs, a loan reuses the block the previous sample freed.
//!
//! Events are iceoryx2's stock ones (`event::recommended::Ipc`: counters in shared memory, a
//! blocked listener woken through a Unix datagram socket), so that clients on stock
//! iceoryx2 (the PyPI `iceoryx2` package, C, C++) wake agp processes and are woken by them.
//! iceoryx2 names a listener's shared memory by a hash of the event type, so a process with
//! any other event type opens every service and moves samples but never meets a listener of
//! ours, silently (`notify` reaches 0 listeners): docs/stock-clients/FINDINGS.md. A listener
//! has a file descriptor, which [`crate::Waiter`] blocks on (`wait.rs`).
//!
//! Every process of one instance must use this type.

use core::fmt::Debug;
use core::ptr::NonNull;
use std::alloc::Layout;
use std::cell::Cell;

use iceoryx2::service::Service;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_cal::arc_sync_policy::{ArcSyncPolicy, ArcSyncPolicyCreationError, LockGuard};
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::{
    bag, dynamic_storage, event, hash, monitoring, reactor, resizable_shared_memory, serialize,
    shared_memory, static_storage, zero_copy_connection,
};

/// The largest event id of every event service of an instance. Processes notify with the
/// default id 0 only, and each wait ends by sweeping the counters of every id up to this
/// one: at iceoryx2's default of 255 that sweep took about 1.3 us of every receive.
pub const EVENT_ID_MAX_VALUE: usize = 0;

/// The iceoryx2 service type of every agp process (see the module documentation).
#[derive(Debug, Clone)]
pub struct AgpIpc {}

impl Service for AgpIpc {
    type StaticStorage = static_storage::recommended::Ipc;
    type ConfigSerializer = serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        crate::owner_only_storage::OwnerOnlyStorage<T>;
    type Bag = bag::recommended::Recommended;
    type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<T>;
    type ServiceNameHasher = hash::recommended::Recommended;
    type SharedMemory = shared_memory::recommended::Ipc<PoolAllocator>;
    type ResizableSharedMemory = resizable_shared_memory::recommended::Ipc<PoolAllocator>;
    type Connection = zero_copy_connection::recommended::Ipc;
    type Event = event::recommended::Ipc;
    type Monitoring = monitoring::recommended::Ipc;
    type Reactor = reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> = PooledRc<T>;
    type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<KeyType>;
    type BlackboardPayload = shared_memory::recommended::Ipc<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

// iceoryx2's service operations (removal, stale-resource cleanup) are default methods of
// this trait, written for any service type.
impl iceoryx2::service::internal::ServiceInternal<AgpIpc> for AgpIpc {}

/// One block of the pool: large and aligned enough for every state iceoryx2 0.10 keeps
/// behind the policy (a loan's is 48 bytes); a larger one goes to the heap.
const BLOCK_BYTES: usize = 256;
const BLOCK_ALIGN: usize = 64;
/// Blocks taken from the heap at once when a thread's free list runs dry.
const BLOCKS_PER_REFILL: usize = 64;

thread_local! {
    /// This thread's free blocks, linked through their first word. No destructor: the
    /// blocks outlive the thread (a reference dropped during thread exit still finds it).
    static FREE: Cell<*mut u8> = const { Cell::new(core::ptr::null_mut()) };
}

/// A free block of this thread, refilling the list from the heap when it is empty.
fn take_block() -> Option<NonNull<u8>> {
    FREE.with(|free| {
        if free.get().is_null() {
            let layout = Layout::from_size_align(BLOCK_BYTES * BLOCKS_PER_REFILL, BLOCK_ALIGN)
                .expect("a valid refill layout");
            // SAFETY: a non-zero size. The memory is never freed: blocks go back to a
            // free list, and a thread's list lives as long as the process.
            let base = unsafe { std::alloc::alloc(layout) };
            if base.is_null() {
                return None;
            }
            let mut next = core::ptr::null_mut::<u8>();
            for i in (0..BLOCKS_PER_REFILL).rev() {
                // SAFETY: block i lies inside the allocation, aligned to BLOCK_ALIGN.
                let block = unsafe { base.add(i * BLOCK_BYTES) };
                // SAFETY: the block is fresh memory nothing else points to, BLOCK_BYTES
                // long and aligned to BLOCK_ALIGN: room and alignment for one pointer.
                unsafe { block.cast::<*mut u8>().write(next) };
                next = block;
            }
            free.set(next);
        }
        let head = free.get();
        // SAFETY: a free block holds the next free block's address in its first word.
        free.set(unsafe { head.cast::<*mut u8>().read() });
        NonNull::new(head)
    })
}

/// Returns a block to this thread's free list.
///
/// # Safety
/// `block` came from [`take_block`] on this thread and nothing uses it any more.
unsafe fn give_block(block: NonNull<u8>) {
    FREE.with(|free| {
        // SAFETY: the caller gives the block up (it came from `take_block` on this thread
        // and nothing uses it), so its first word is ours to overwrite; every block is
        // BLOCK_BYTES long and BLOCK_ALIGN aligned, room and alignment for a pointer.
        unsafe { block.as_ptr().cast::<*mut u8>().write(free.get()) };
        free.set(block.as_ptr());
    });
}

struct Inner<T> {
    strong: Cell<usize>,
    value: T,
}

/// A single-threaded reference-counted `T` (like `Rc<T>`, and like it neither `Send` nor
/// `Sync`) whose memory comes from a per-thread pool of blocks instead of one heap
/// allocation per value. iceoryx2 uses it as the [`AgpIpc`] service's
/// `ArcThreadSafetyPolicy`.
pub struct PooledRc<T> {
    inner: NonNull<Inner<T>>,
}

impl<T> PooledRc<T> {
    /// Whether values of `T` fit a pool block (else each lives in its own heap allocation).
    pub const fn fits_a_block() -> bool {
        let layout = Layout::new::<Inner<T>>();
        layout.size() <= BLOCK_BYTES && layout.align() <= BLOCK_ALIGN
    }

    /// Moves `value` into a block of this thread's pool, or onto the heap when it does not
    /// fit one. `None` only when the heap is exhausted.
    pub fn try_new(value: T) -> Option<Self> {
        let inner = Inner {
            strong: Cell::new(1),
            value,
        };
        if Self::fits_a_block() {
            let block = take_block()?.cast::<Inner<T>>();
            // SAFETY: the block is free, large and aligned enough for `Inner<T>`.
            unsafe { block.as_ptr().write(inner) };
            Some(Self { inner: block })
        } else {
            Some(Self {
                inner: NonNull::from(Box::leak(Box::new(inner))),
            })
        }
    }

    fn inner(&self) -> &Inner<T> {
        // SAFETY: alive while any reference is.
        unsafe { self.inner.as_ref() }
    }

    /// References to this value, this one included.
    pub fn strong_count(&self) -> usize {
        self.inner().strong.get()
    }

    /// Frees the memory of `inner`, whose value was dropped or abandoned.
    ///
    /// # Safety
    /// Called once, by the last reference, on the thread that made it.
    unsafe fn release(&self) {
        if Self::fits_a_block() {
            // SAFETY: a `T` that fits a block was put in one by `try_new`, from this
            // thread's pool: `PooledRc` is neither `Send` nor `Sync`, so the last
            // reference is on the thread that made it, and after it nothing uses the block.
            unsafe { give_block(self.inner.cast()) };
        } else {
            // SAFETY: a `T` that does not fit a block was boxed and leaked by `try_new`, so
            // the pointer is a `Box`'s; `ManuallyDrop` (same layout as `Inner<T>`) frees the
            // memory without dropping the value, which the caller dropped or abandoned.
            drop(unsafe {
                Box::from_raw(
                    self.inner
                        .as_ptr()
                        .cast::<core::mem::ManuallyDrop<Inner<T>>>(),
                )
            });
        }
    }
}

impl<T> core::ops::Deref for PooledRc<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.inner().value
    }
}

impl<T> Clone for PooledRc<T> {
    fn clone(&self) -> Self {
        let strong = &self.inner().strong;
        strong.set(strong.get() + 1);
        Self { inner: self.inner }
    }
}

impl<T> Drop for PooledRc<T> {
    fn drop(&mut self) {
        let strong = &self.inner().strong;
        let left = strong.get() - 1;
        strong.set(left);
        if left == 0 {
            // SAFETY: the last reference: the value is dropped once, then its memory freed.
            unsafe {
                core::ptr::drop_in_place(&mut (*self.inner.as_ptr()).value);
                self.release();
            }
        }
    }
}

impl<T: Debug> Debug for PooledRc<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_tuple("PooledRc").field(&**self).finish()
    }
}

impl<T: Send + Debug + Abandonable> Abandonable for PooledRc<T> {
    unsafe fn abandon_in_place(this: NonNull<Self>) {
        // As iceoryx2's own single-threaded policy: the last reference abandons the value
        // (and leaves its memory), any other just lets go of its share.
        // SAFETY: the caller promises `this` points to a valid, constructed, not yet dropped
        // `PooledRc` (the trait's contract), so it may be borrowed for this call.
        let this = unsafe { this.as_ref() };
        if this.strong_count() == 1 {
            // SAFETY: the last reference: the value is alive (never dropped, as `this`
            // was not) and nobody else can reach it, so it is abandoned once, in place; the
            // pointer to a field of a live allocation is non-null.
            unsafe {
                T::abandon_in_place(NonNull::new_unchecked(core::ptr::addr_of_mut!(
                    (*this.inner.as_ptr()).value
                )))
            };
        } else {
            let strong = &this.inner().strong;
            strong.set(strong.get() - 1);
        }
    }
}

/// Access to a [`PooledRc`]'s value for as long as the policy is borrowed.
pub struct PooledGuard<'parent, T> {
    value: &'parent T,
}

impl<T> core::ops::Deref for PooledGuard<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.value
    }
}

impl<'parent, T: Send + Abandonable> LockGuard<'parent, T> for PooledGuard<'parent, T> {}

impl<T: Send + Debug + Abandonable> ArcSyncPolicy<T> for PooledRc<T> {
    type LockGuard<'parent>
        = PooledGuard<'parent, T>
    where
        Self: 'parent,
        T: 'parent;

    fn new(value: T) -> Result<Self, ArcSyncPolicyCreationError> {
        Self::try_new(value).ok_or(ArcSyncPolicyCreationError::InsufficientResources)
    }

    fn lock(&self) -> Self::LockGuard<'_> {
        PooledGuard { value: &**self }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::rc::Rc;

    #[test]
    fn a_value_is_dropped_once_when_its_last_reference_goes() {
        let dropped = Rc::new(Cell::new(0));
        struct Probe(Rc<Cell<u32>>);
        impl Drop for Probe {
            fn drop(&mut self) {
                self.0.set(self.0.get() + 1);
            }
        }
        let a = PooledRc::try_new(Probe(dropped.clone())).expect("memory");
        let b = a.clone();
        assert_eq!(a.strong_count(), 2);
        drop(a);
        assert_eq!(dropped.get(), 0, "dropped while a reference was left");
        assert_eq!(b.strong_count(), 1);
        drop(b);
        assert_eq!(dropped.get(), 1);
    }

    #[test]
    fn a_freed_block_is_the_next_one_handed_out() {
        let a = PooledRc::try_new([7u64; 6]).expect("memory");
        let first = a.inner.as_ptr() as usize;
        drop(a);
        let b = PooledRc::try_new([9u64; 6]).expect("memory");
        assert_eq!(b.inner.as_ptr() as usize, first, "the block was not reused");
        assert_eq!(*b, [9u64; 6]);
    }

    #[test]
    fn live_values_never_share_a_block_and_keep_their_contents() {
        // More than one refill's worth, all alive at once.
        let values: Vec<PooledRc<[u32; 8]>> = (0..3 * BLOCKS_PER_REFILL as u32)
            .map(|i| PooledRc::try_new([i; 8]).expect("memory"))
            .collect();
        let mut addresses: Vec<usize> = values.iter().map(|v| v.inner.as_ptr() as usize).collect();
        addresses.sort_unstable();
        addresses.dedup();
        assert_eq!(addresses.len(), values.len());
        assert!(addresses.iter().all(|a| a % BLOCK_ALIGN == 0));
        for (i, v) in values.iter().enumerate() {
            assert_eq!(**v, [i as u32; 8]);
        }
    }

    #[test]
    fn a_value_too_large_for_a_block_lives_on_the_heap() {
        assert!(!PooledRc::<[u8; 1024]>::fits_a_block());
        let big = PooledRc::try_new([3u8; 1024]).expect("memory");
        let again = big.clone();
        drop(big);
        assert_eq!(again[1023], 3);
    }
}
