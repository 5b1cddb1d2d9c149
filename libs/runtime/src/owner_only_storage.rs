//! iceoryx2's persistent POSIX shared-memory storage with its one world-writable use turned
//! owner-only.
//!
//! iceoryx2 0.10 creates a node's global management segment (`<prefix>….global_mgmt` in
//! `/dev/shm`, a counter it draws node ids from) with "global access": `fchmod` to 0666
//! after initialisation, past any umask. Another user who wrote into it stopped every new
//! node of the instance (`UnableToGenerateUniqueNodeId`). [`OwnerOnlyStorage`] is that same
//! storage with `enable_global_access` ignored, so the segment ends 0600 like every other
//! segment of an instance; only processes of the same user (all of an instance's) open it.

use core::fmt::Debug;
use core::mem::MaybeUninit;
use core::ptr::NonNull;
use core::time::Duration;

use iceoryx2::prelude::{FileName, Path};
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_bb_memory::bump_allocator::BumpAllocator;
use iceoryx2_bb_posix::file::AccessMode;
use iceoryx2_cal::dynamic_storage::posix_shared_memory::{Builder, Configuration, Storage};
use iceoryx2_cal::dynamic_storage::{
    DynamicStorage, DynamicStorageBuilder, DynamicStorageCreateError, DynamicStorageOpenError,
    DynamicStorageOpenOrCreateError,
};
use iceoryx2_cal::named_concept::{
    NamedConcept, NamedConceptBuilder, NamedConceptDoesExistError, NamedConceptListError,
    NamedConceptMgmt, NamedConceptPathHintRemoveError, NamedConceptRemoveError,
};

/// iceoryx2's POSIX shared-memory [`DynamicStorage`], never world-accessible.
#[derive(Debug)]
pub struct OwnerOnlyStorage<T: Debug + Send + Sync + ZeroCopySend>(Storage<T>);

/// Builds an [`OwnerOnlyStorage`]: iceoryx2's builder with global access refused.
#[derive(Debug)]
pub struct OwnerOnlyBuilder<'builder, T: Debug + Send + Sync + ZeroCopySend>(Builder<'builder, T>);

impl<T: Debug + Send + Sync + ZeroCopySend> NamedConceptBuilder<OwnerOnlyStorage<T>>
    for OwnerOnlyBuilder<'_, T>
{
    fn new(name: &FileName) -> Self {
        Self(<Builder<'_, T> as NamedConceptBuilder<Storage<T>>>::new(
            name,
        ))
    }

    fn config(self, config: &Configuration<T>) -> Self {
        Self(self.0.config(config))
    }
}

impl<'builder, T: Debug + Send + Sync + ZeroCopySend>
    DynamicStorageBuilder<'builder, T, OwnerOnlyStorage<T>> for OwnerOnlyBuilder<'builder, T>
{
    fn has_ownership(self, value: bool) -> Self {
        Self(self.0.has_ownership(value))
    }

    /// Ignored: the storage stays readable and writable by its owner only.
    fn enable_global_access(self, _value: bool) -> Self {
        Self(self.0.enable_global_access(false))
    }

    fn supplementary_size(self, value: usize) -> Self {
        Self(self.0.supplementary_size(value))
    }

    fn timeout(self, value: Duration) -> Self {
        Self(self.0.timeout(value))
    }

    fn initializer<F: FnMut(&mut MaybeUninit<T>, &mut BumpAllocator) -> bool + 'builder>(
        self,
        value: F,
    ) -> Self {
        Self(self.0.initializer(value))
    }

    fn create(self) -> Result<OwnerOnlyStorage<T>, DynamicStorageCreateError> {
        self.0.create().map(OwnerOnlyStorage)
    }

    fn open(self, access_mode: AccessMode) -> Result<OwnerOnlyStorage<T>, DynamicStorageOpenError> {
        self.0.open(access_mode).map(OwnerOnlyStorage)
    }

    fn open_or_create(self) -> Result<OwnerOnlyStorage<T>, DynamicStorageOpenOrCreateError> {
        self.0.open_or_create().map(OwnerOnlyStorage)
    }
}

impl<T: Debug + Send + Sync + ZeroCopySend> Abandonable for OwnerOnlyStorage<T> {
    unsafe fn abandon_in_place(mut this: NonNull<Self>) {
        // SAFETY: the caller's guarantees for `this` hold for the storage it wraps.
        unsafe { Storage::abandon_in_place(NonNull::from_mut(&mut this.as_mut().0)) };
    }
}

impl<T: Debug + Send + Sync + ZeroCopySend> NamedConcept for OwnerOnlyStorage<T> {
    fn name(&self) -> &FileName {
        self.0.name()
    }
}

impl<T: Debug + Send + Sync + ZeroCopySend> NamedConceptMgmt for OwnerOnlyStorage<T> {
    type Configuration = Configuration<T>;

    fn does_exist_cfg(
        name: &FileName,
        cfg: &Self::Configuration,
    ) -> Result<bool, NamedConceptDoesExistError> {
        Storage::<T>::does_exist_cfg(name, cfg)
    }

    fn list_cfg(cfg: &Self::Configuration) -> Result<Vec<FileName>, NamedConceptListError> {
        Storage::<T>::list_cfg(cfg)
    }

    unsafe fn remove_cfg(
        name: &FileName,
        cfg: &Self::Configuration,
    ) -> Result<bool, NamedConceptRemoveError> {
        // SAFETY: the caller's guarantees are those of the wrapped storage's removal.
        unsafe { Storage::<T>::remove_cfg(name, cfg) }
    }

    fn remove_path_hint(value: &Path) -> Result<(), NamedConceptPathHintRemoveError> {
        Storage::<T>::remove_path_hint(value)
    }
}

impl<T: Debug + Send + Sync + ZeroCopySend> DynamicStorage<T> for OwnerOnlyStorage<T> {
    type Builder<'builder> = OwnerOnlyBuilder<'builder, T>;

    fn does_support_persistency() -> bool {
        Storage::<T>::does_support_persistency()
    }

    fn has_ownership(&self) -> bool {
        self.0.has_ownership()
    }

    fn release_ownership(&self) {
        self.0.release_ownership();
    }

    fn acquire_ownership(&self) {
        self.0.acquire_ownership();
    }

    fn get(&self) -> &T {
        self.0.get()
    }

    unsafe fn __internal_set_type_name_in_config(
        config: &mut Self::Configuration,
        type_name: &str,
    ) {
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { Storage::<T>::__internal_set_type_name_in_config(config, type_name) }
    }
}
