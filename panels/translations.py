"""The add-on's words for Blender's translation system (bpy.app.translations): a language's table maps
(context, English text) to its text. Labels built in code use the English text with str.format's {} as
the key, so one entry serves every value. French is the first table; another language is another dict."""
import bpy

# Operator labels are looked up in Blender's "Operator" context, everything else in the default "*".
_FRENCH_OPERATORS = {
    "Run All": "Tout lancer", "Convert": "Convertir", "Estimate Light": "Estimer la lumière",
    "Adapt": "Adapter", "Compose": "Composer", "Bake Asset": "Cuire l'asset", "Import Asset": "Importer l'asset",
    "Pick Placement": "Choisir l'emplacement", "Pick Sun": "Choisir le soleil", "Match Camera": "Caler la caméra",
    "Write Prompt": "Écrire le prompt", "Open Folder": "Ouvrir le dossier", "Copy Details": "Copier les détails",
    "Cancel": "Annuler", "Resume": "Reprendre", "Apply Run": "Appliquer l'essai", "Delete Run": "Supprimer l'essai",
    "Export to Mitsuba": "Exporter vers Mitsuba", "Open Composite": "Ouvrir le composite",
    "Sun from Light": "Soleil depuis la lampe", "Use Result": "Utiliser le résultat", "Compare": "Comparer",
    "Add UV Map": "Ajouter une carte UV",
}
_FRENCH = {
    "Asset": "Asset", "Scene": "Scène", "Style": "Style", "Quality": "Qualité", "Run": "Lancer",
    "Results": "Résultats", "Photo": "Photo", "Placement": "Emplacement", "Size": "Taille", "Turn": "Rotation",
    "Camera": "Caméra", "Sun": "Soleil", "Prompt": "Prompt", "Preset": "Préréglage", "Output": "Sortie",
    "An earlier SceneFit downloaded models into {}": "Une version antérieure de SceneFit a téléchargé des modèles dans {}",
    "Material": "Matériau", "World": "Monde", "Original": "Original", "Details": "Détails", "Result": "Résultat",
    "Composite": "Composite", "Slot": "Emplacement de matériau", "(empty)": "(vide)",
    "Bake Asset…": "Cuire l'asset…", "Modules missing": "Modules manquants", "Unsaved file": "Fichier non enregistré",
    "No UV map": "Pas de carte UV", "Material not readable": "Matériau illisible",
    "{} objects, one asset": "{} objets, un seul asset", "'{}' is flat": "« {} » est plat",
    "{} inputs dropped": "{} entrées ignorées", "Camera: {}": "Caméra : {}", "Runs of '{}'": "Essais de « {} »",
    "(the example asset on a {})": "(l'asset d'exemple sur un {})", "{:.0f} s": "{:.0f} s", "{:.0f} min": "{:.0f} min",
    "{:.1f} h": "{:.1f} h", "{:.1f} days": "{:.1f} jours", "{}: about {:.0f} s": "{} : environ {:.0f} s",
    "{}: under 1 s": "{} : moins d'une seconde", "{}: not measured yet": "{} : pas encore mesuré",
    "adapt: not measured yet": "adaptation : pas encore mesurée",
    "adapt: about {} on a CPU, {} on an H200 (SD2 size)": "adaptation : environ {} sur un CPU, {} sur une H200 "
                                                          "(taille SD2)",
    "{}: stage {} of {}": "{} : étape {} sur {}", "about {} left": "encore environ {}",
    "Results are packed into the unsaved file; save it first to keep them as files beside it.":
        "Les résultats sont intégrés au fichier non enregistré ; enregistrez-le d'abord pour les garder en fichiers "
        "à côté.",
    "The mesh has no UV map: unwrap it first (UV > Smart UV Project).":
        "Le maillage n'a pas de carte UV : dépliez-le d'abord (UV > Smart UV Project).",
    "flat": "plat", "Not read: {}": "Non lu : {}", "{:.0f} times as wide as tall": "{:.0f} fois plus large que haut",
    "'{}' is {} (a ground plane?): deselect it to fit the rest":
        "« {} » est {} (un plan de sol ?) : désélectionnez-le pour ajuster le reste",
    "The scene camera '{}' shows the photo: the asset is composed where it stands in its view":
        "La caméra de la scène « {} » montre la photo : l'asset est composé là où il se trouve dans sa vue",
    "on this GPU for about {} (measured on {} with models of Stable Diffusion 2's size; smaller GPUs take longer)":
        "sur ce GPU pendant environ {} (mesuré sur {} avec des modèles de la taille de Stable Diffusion 2 ; les GPU "
        "plus petits prennent plus longtemps)",
    "on this CPU for about {} (measured with models of Stable Diffusion 2's size on a 2-core CPU)":
        "sur ce CPU pendant environ {} (mesuré avec des modèles de la taille de Stable Diffusion 2 sur un CPU à 2 "
        "cœurs)",
    "The latest preview is the image '{}': open it in an Image Editor to see it larger":
        "Le dernier aperçu est l'image « {} » : ouvrez-la dans un éditeur d'images pour la voir en grand",
    "adapt: about {} on a CPU": "adaptation : environ {} sur un CPU",
    "finished": "terminé", "cancelled": "annulé", "failed": "échoué", "cancelled, resumable": "annulé, reprenable",
}

translations_dict = {"fr_FR": {**{("*", k): v for k, v in _FRENCH.items()},
                               **{("Operator", k): v for k, v in _FRENCH_OPERATORS.items()}}}


def register() -> None:
    bpy.app.translations.register(__package__, translations_dict)


def unregister() -> None:
    bpy.app.translations.unregister(__package__)
